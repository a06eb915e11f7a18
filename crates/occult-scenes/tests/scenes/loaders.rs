//! Round trips and bad input for the file loaders, on small files written by the tests into a
//! scratch folder under Cargo's target directory.
//!
//! Round trips check triangle counts (fan triangulation), positions, bounds, colors and the
//! instancing of glTF meshes. Bad input checks that every malformed file is an `Err` whose message
//! names the file (DESIGN invariant 5), and that no prefix or single-byte corruption of a valid
//! file makes a loader panic.

use std::path::{Path, PathBuf};

use occult_core::{MeshColors, NodeKind, Scene, Vec3, MAX_FLATTEN_TRIANGLES};
use occult_scenes::load::{load_bytes, load_file, LoadError, LoadedScene, Location};

// ---------------------------------------------------------------------------------------------
// Helpers

/// A fresh, empty scratch folder for one test.
fn scratch(test_name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("occult-loaders")
        .join(test_name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch folder");
    dir
}

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}

fn load_ok(path: &Path) -> LoadedScene {
    load_file(path).unwrap_or_else(|e| panic!("{} should load: {e}", path.display()))
}

/// Loads a file that must fail; checks that the message names the file, returns the error.
fn load_err(path: &Path) -> LoadError {
    match load_file(path) {
        Ok(loaded) => panic!(
            "{} should fail but loaded {} triangles",
            path.display(),
            loaded.scene.item_count()
        ),
        Err(e) => {
            let name = path.file_name().expect("file name").to_string_lossy().into_owned();
            assert!(e.to_string().contains(&name), "error '{e}' does not name {name}");
            assert_eq!(e.path(), path);
            e
        }
    }
}

/// Asserts that `e` is an index out of range naming `index` (as written in the file) and the
/// `vertex_count` it may refer to.
fn assert_index_out_of_range(e: &LoadError, index: i64, vertex_count: u64) {
    assert!(
        matches!(
            e,
            LoadError::IndexOutOfRange { index: i, vertex_count: n, .. } if *i == index && *n == vertex_count
        ),
        "{e}"
    );
}

/// All triangles of a scene in world space, in item order.
fn world_triangles(scene: &Scene) -> Vec<[Vec3; 3]> {
    let flat = scene.flatten(MAX_FLATTEN_TRIANGLES).expect("flatten");
    (0..flat.triangle_count()).map(|t| flat.triangle_positions(t)).collect()
}

fn mesh_count(scene: &Scene) -> usize {
    scene
        .nodes()
        .iter()
        .filter(|n| matches!(n.kind(), NodeKind::Mesh(_)))
        .count()
}

// ---------------------------------------------------------------------------------------------
// OBJ round trips

/// A unit square (quad), a pentagon at z = 1, and a triangle at z = 2.
const OBJ_POLYGONS: &str = "\
# quads and a pentagon
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 2 0 1
v 3 1 1
v 1 2 1
v -1 1 1
v 0 0 2
v 1 0 2
v 0 1 2
f 1 2 3 4
f 5 6 7 8 9
f 10 11 12
";

#[test]
fn obj_quads_and_pentagon_are_fan_triangulated() {
    let dir = scratch("obj_quads_and_pentagon_are_fan_triangulated");
    let loaded = load_ok(&write(&dir, "polygons.obj", OBJ_POLYGONS));
    let scene = &loaded.scene;
    assert_eq!(scene.item_count(), 2 + 3 + 1);
    assert_eq!(mesh_count(scene), 1);
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_eq!(scene.bounds().min, Vec3::new(-1.0, 0.0, 0.0));
    assert_eq!(scene.bounds().max, Vec3::new(3.0, 2.0, 2.0));
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let triangles = world_triangles(scene);
    // Fans around the first corner: (p0 p1 p2), (p0 p2 p3), ...
    assert_eq!(triangles[0], [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.)]);
    assert_eq!(triangles[1], [v(0., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)]);
    assert_eq!(triangles[2], [v(0., 0., 1.), v(2., 0., 1.), v(3., 1., 1.)]);
    assert_eq!(triangles[4], [v(0., 0., 1.), v(1., 2., 1.), v(-1., 1., 1.)]);
    assert_eq!(triangles[5], [v(0., 0., 2.), v(1., 0., 2.), v(0., 1., 2.)]);
}

#[test]
fn obj_corner_forms_relative_indices_crlf_and_comments() {
    let dir = scratch("obj_corner_forms_relative_indices_crlf_and_comments");
    let text = "v 0 0 0\r\nv 1 0 0 1.0\r\nv 0 1 0 # a comment\r\nvt 0 0\r\nvt 1 0\r\nvn 0 0 1\r\n\
                f 1/1 2/2/1 3//1\r\nf -3 -2 -1\r\ns off\r\nl 1 2\r\n";
    let loaded = load_ok(&write(&dir, "forms.OBJ", text));
    assert_eq!(loaded.scene.item_count(), 2);
    assert_eq!(loaded.scene.bounds().max, Vec3::new(1.0, 1.0, 0.0));
    // The `l` statement is ignored with a warning.
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
}

const MTL_TWO_COLORS: &str = "\
newmtl red
Kd 1.0 0.0 0.0
map_Kd -s 1 1 1 bricks.png
newmtl gray
Kd 0.5
";

/// Two objects; the second switches material, so there are three (object, material) meshes.
const OBJ_WITH_MATERIALS: &str = "\
mtllib colors.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
o wall
usemtl red
f 1 2 3 4
o floor
usemtl gray
f 1 2 3
usemtl red
f 1 3 4
";

#[test]
fn obj_materials_give_per_mesh_colors() {
    let dir = scratch("obj_materials_give_per_mesh_colors");
    write(&dir, "colors.mtl", MTL_TWO_COLORS);
    write(&dir, "bricks.png", b"not decoded");
    let loaded = load_ok(&write(&dir, "rooms.obj", OBJ_WITH_MATERIALS));
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let scene = &loaded.scene;
    assert_eq!(scene.item_count(), 4);
    assert_eq!(mesh_count(scene), 3);
    let mut colors: Vec<(String, Option<MeshColors>)> = scene
        .nodes()
        .iter()
        .filter_map(|n| n.mesh().map(|m| (n.name().to_string(), m.colors().cloned())))
        .collect();
    colors.sort_by(|a, b| a.0.cmp(&b.0));
    assert_eq!(
        colors,
        vec![
            (
                "floor [gray]".to_string(),
                Some(MeshColors::PerMesh([128, 128, 128, 255]))
            ),
            ("floor [red]".to_string(), Some(MeshColors::PerMesh([255, 0, 0, 255]))),
            ("wall".to_string(), Some(MeshColors::PerMesh([255, 0, 0, 255]))),
        ]
    );
    // Each mesh keeps only the vertices it uses.
    for node in scene.nodes() {
        if let Some(mesh) = node.mesh() {
            assert_eq!(
                mesh.positions().len(),
                if node.name() == "wall" { 4 } else { 3 },
                "{}",
                node.name()
            );
        }
    }
}

#[test]
fn obj_missing_mtl_and_missing_texture_are_warnings() {
    let dir = scratch("obj_missing_mtl_and_missing_texture_are_warnings");
    let loaded = load_ok(&write(&dir, "no_library.obj", OBJ_WITH_MATERIALS));
    assert_eq!(loaded.scene.item_count(), 4);
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("colors.mtl"), "{}", loaded.warnings[0]);
    assert!(loaded
        .scene
        .nodes()
        .iter()
        .filter_map(|n| n.mesh())
        .all(|m| m.colors().is_none()));

    write(&dir, "colors.mtl", MTL_TWO_COLORS);
    let loaded = load_ok(&dir.join("no_library.obj"));
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("bricks.png"), "{}", loaded.warnings[0]);
}

/// A model may name any file as a companion; one that never ends (a device) must not hang the
/// load or exhaust memory: only regular files are read.
#[cfg(unix)]
#[test]
fn companions_that_are_devices_are_not_read() {
    let dir = scratch("companions_that_are_devices_are_not_read");
    let obj = "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let loaded = load_ok(&write(&dir, "device.obj", obj));
    assert_eq!(loaded.scene.item_count(), 1);
    assert!(
        loaded.warnings.iter().any(|w| w.contains("/dev/zero")),
        "{:?}",
        loaded.warnings
    );
    let gltf = quad_gltf(r#"{"uri": "file:///dev/zero", "byteLength": 60}"#);
    let e = load_err(&write(&dir, "device.gltf", gltf));
    assert!(matches!(e, LoadError::Buffer { .. }), "{e}");
}

/// Library and texture checks stay linear: a library named 2,000 times is read once, and
/// 20,000 distinct missing textures make one warning listing a few of them.
#[test]
fn many_libraries_and_textures_stay_linear() {
    let dir = scratch("many_libraries_and_textures_stay_linear");
    let mtl: String = (0..20_000).map(|i| format!("map_Kd missing_{i}.png\n")).collect();
    write(&dir, "big.mtl", format!("newmtl a\nKd 1 0 0\n{mtl}"));
    let obj = format!(
        "{}usemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "mtllib big.mtl\n".repeat(2_000)
    );
    let loaded = load_ok(&write(&dir, "many.obj", obj));
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(
        loaded.warnings[0].starts_with(&format!("{}: 20000 texture files", dir.join("big.mtl").display())),
        "{}",
        loaded.warnings[0]
    );
}

// ---------------------------------------------------------------------------------------------
// PLY round trips

fn push_f32(bytes: &mut Vec<u8>, value: f32, big_endian: bool) {
    bytes.extend(if big_endian {
        value.to_be_bytes()
    } else {
        value.to_le_bytes()
    });
}

fn push_u32(bytes: &mut Vec<u8>, value: u32, big_endian: bool) {
    bytes.extend(if big_endian {
        value.to_be_bytes()
    } else {
        value.to_le_bytes()
    });
}

fn push_u16(bytes: &mut Vec<u8>, value: u16, big_endian: bool) {
    bytes.extend(if big_endian {
        value.to_be_bytes()
    } else {
        value.to_le_bytes()
    });
}

/// Corners of the PLY test meshes: a unit square and a point above it.
const PLY_VERTICES: [[f32; 3]; 5] = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [0.5, 0.5, 2.]];

const PLY_ASCII: &str = "\
ply
format ascii 1.0
comment like the Stanford bunny: extra vertex properties
element vertex 5
property float x
property float y
property float z
property float confidence
property float intensity
element face 3
property list uchar int vertex_indices
end_header
0 0 0 0.85 0.5
1 0 0 .9 0.5
1.0 1 0 0.39 5.
0 1 0 1 1
0.5 0.5 2e0 1 1
4 0 1 2 3
3 0 1 4
3 1 2 4
";

#[test]
fn ply_ascii_with_extra_vertex_properties() {
    let dir = scratch("ply_ascii_with_extra_vertex_properties");
    let loaded = load_ok(&write(&dir, "bunny_like.ply", PLY_ASCII));
    let scene = &loaded.scene;
    assert_eq!(scene.item_count(), 2 + 1 + 1);
    assert_eq!(scene.bounds().min, Vec3::ZERO);
    assert_eq!(scene.bounds().max, Vec3::new(1.0, 1.0, 2.0));
    let mesh = scene.node(scene.root()).mesh().expect("one mesh");
    assert_eq!(mesh.positions().len(), 5);
    assert_eq!(mesh.triangles(), &[[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 4]]);
    assert_eq!(mesh.positions()[4], Vec3::new(0.5, 0.5, 2.0));
}

/// A binary PLY with properties before and after x, y, z, a property on the face before the
/// list, an ignored element between vertex and face, and the index list type given.
fn ply_binary(big_endian: bool, index_list: &str) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut bytes = format!(
        "ply\nformat {format} 1.0\nelement vertex 5\nproperty uchar flags\nproperty float x\nproperty float y\n\
         property float z\nproperty float confidence\nproperty float intensity\nelement edge 1\n\
         property int vertex1\nproperty int vertex2\nelement face 3\nproperty uchar intensity\n\
         property {index_list}\nend_header\n"
    )
    .into_bytes();
    for p in PLY_VERTICES {
        bytes.push(7);
        for c in p {
            push_f32(&mut bytes, c, big_endian);
        }
        push_f32(&mut bytes, 0.75, big_endian);
        push_f32(&mut bytes, 0.5, big_endian);
    }
    push_u32(&mut bytes, 0, big_endian);
    push_u32(&mut bytes, 1, big_endian);
    let wide = !index_list.contains("short");
    for face in [&[0u32, 1, 2, 3][..], &[0, 1, 4], &[1, 2, 4]] {
        bytes.push(200);
        bytes.push(face.len() as u8);
        for &i in face {
            if wide {
                push_u32(&mut bytes, i, big_endian);
            } else {
                push_u16(&mut bytes, i as u16, big_endian);
            }
        }
    }
    bytes
}

/// Writes [`ply_binary`]`(big_endian, index_list)` as `dir/name`, loads it and checks the scene.
fn check_ply_binary(dir: &Path, name: &str, big_endian: bool, index_list: &str) {
    let loaded = load_ok(&write(dir, name, ply_binary(big_endian, index_list)));
    let scene = &loaded.scene;
    assert_eq!(scene.item_count(), 4);
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let mesh = scene.node(scene.root()).mesh().expect("one mesh");
    let positions: Vec<[f32; 3]> = mesh.positions().iter().map(|p| p.to_array()).collect();
    assert_eq!(positions, PLY_VERTICES.to_vec());
    assert_eq!(mesh.triangles(), &[[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 4]]);
    assert_eq!(scene.bounds().max, Vec3::new(1.0, 1.0, 2.0));
}

#[test]
fn ply_binary_little_endian_with_extra_properties() {
    let dir = scratch("ply_binary_little_endian_with_extra_properties");
    check_ply_binary(&dir, "le.ply", false, "list uchar int vertex_indices");
}

#[test]
fn ply_binary_big_endian_with_extra_properties() {
    let dir = scratch("ply_binary_big_endian_with_extra_properties");
    check_ply_binary(&dir, "be.ply", true, "list uchar uint vertex_indices");
    // Other index widths and the `vertex_index` spelling.
    check_ply_binary(&dir, "be16.ply", true, "list uint8 ushort vertex_index");
}

#[test]
fn ply_tristrips_with_restarts() {
    let dir = scratch("ply_tristrips_with_restarts");
    let text = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n\
                element tristrips 1\nproperty list int int vertex_indices\nend_header\n\
                0 0 0\n1 0 0\n0 1 0\n1 1 0\n0.5 0.5 1\n8 0 1 2 3 -1 0 1 4\n";
    let loaded = load_ok(&write(&dir, "strips.ply", text));
    let mesh = loaded.scene.node(loaded.scene.root()).mesh().expect("one mesh");
    assert_eq!(mesh.triangles(), &[[0, 1, 2], [2, 1, 3], [0, 1, 4]]);
}

// ---------------------------------------------------------------------------------------------
// glTF round trips

/// Bytes of the test buffer: a unit quad's 4 positions (f32) then 6 u16 indices.
fn quad_buffer() -> Vec<u8> {
    let mut bytes = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
        for c in p {
            bytes.extend(c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bytes.extend(i.to_le_bytes());
    }
    bytes
}

/// A document whose one mesh (a red quad) is used by three nodes: node 0 has the mesh and
/// children 1 (translated) and 2 (matrix: scale 2, then up 3).
fn quad_gltf(buffer: &str) -> String {
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [
    {{"name": "parent", "mesh": 0, "children": [1, 2]}},
    {{"mesh": 0, "translation": [2, 0, 0]}},
    {{"mesh": 0, "matrix": [2,0,0,0, 0,2,0,0, 0,0,2,0, 0,3,0,1]}}
  ],
  "meshes": [{{"name": "quad", "primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
  "materials": [{{"pbrMetallicRoughness": {{"baseColorFactor": [1, 0, 0, 1]}}}}],
  "buffers": [{buffer}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
    )
}

/// A GLB of a JSON document and a binary chunk.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut bytes = Vec::new();
    bytes.extend(b"glTF");
    bytes.extend(2u32.to_le_bytes());
    bytes.extend((total as u32).to_le_bytes());
    bytes.extend((json.len() as u32).to_le_bytes());
    bytes.extend(b"JSON");
    bytes.extend(json);
    bytes.extend((bin.len() as u32).to_le_bytes());
    bytes.extend(b"BIN\0");
    bytes.extend(bin);
    bytes
}

fn quad_glb() -> Vec<u8> {
    glb(&quad_gltf(r#"{"byteLength": 60}"#), &quad_buffer())
}

fn check_quad_scene(loaded: &LoadedScene) {
    let scene = &loaded.scene;
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_eq!(scene.item_count(), 6);
    assert_eq!(scene.unique_triangle_count(), 2);
    assert!(scene.unique_triangle_count() < scene.item_count());
    assert_eq!(mesh_count(scene), 1);
    // The mesh, the group of node 0 and the scene's root group.
    assert_eq!(scene.nodes().len(), 3);
    assert_eq!(scene.bounds().min, Vec3::ZERO);
    assert_eq!(scene.bounds().max, Vec3::new(3.0, 5.0, 0.0));
    let mesh = scene.nodes().iter().find_map(|n| n.mesh()).expect("a mesh");
    assert_eq!(mesh.colors(), Some(&MeshColors::PerMesh([255, 0, 0, 255])));
    let triangles = world_triangles(scene);
    assert_eq!(triangles[0], [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]);
    assert_eq!(
        triangles[2],
        [
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(3.0, 1.0, 0.0)
        ]
    );
    assert_eq!(
        triangles[5],
        [
            Vec3::new(0.0, 3.0, 0.0),
            Vec3::new(2.0, 5.0, 0.0),
            Vec3::new(0.0, 5.0, 0.0)
        ]
    );
}

#[test]
fn gltf_with_external_bin_keeps_instancing() {
    let dir = scratch("gltf_with_external_bin_keeps_instancing");
    write(&dir, "quad data.bin", quad_buffer());
    let path = write(
        &dir,
        "quads.gltf",
        quad_gltf(r#"{"uri": "quad%20data.bin", "byteLength": 60}"#),
    );
    check_quad_scene(&load_ok(&path));
}

#[test]
fn glb_built_by_hand_keeps_instancing() {
    let dir = scratch("glb_built_by_hand_keeps_instancing");
    check_quad_scene(&load_ok(&write(&dir, "quads.GLB", quad_glb())));
}

/// Standard base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[test]
fn gltf_with_data_uri_buffer() {
    let dir = scratch("gltf_with_data_uri_buffer");
    let uri = format!("data:application/octet-stream;base64,{}", base64(&quad_buffer()));
    let path = write(
        &dir,
        "embedded.gltf",
        quad_gltf(&format!(r#"{{"uri": "{uri}", "byteLength": 60}}"#)),
    );
    check_quad_scene(&load_ok(&path));
}

#[test]
fn gltf_sparse_positions_replace_base_values() {
    let dir = scratch("gltf_sparse_positions_replace_base_values");
    // Sparse indices 0 1 2 (the first three u16 of view 1) take the values from byte 12 of
    // view 0: vertices 0, 1, 2 become the quad's vertices 1, 2, 3.
    let json = quad_gltf(r#"{"byteLength": 60}"#).replace(
        r#""count": 4, "type": "VEC3","#,
        r#""count": 4, "type": "VEC3",
           "sparse": {"count": 3, "indices": {"bufferView": 1, "componentType": 5123},
                      "values": {"bufferView": 0, "byteOffset": 12}},"#,
    );
    let loaded = load_ok(&write(&dir, "sparse.glb", glb(&json, &quad_buffer())));
    let triangles = world_triangles(&loaded.scene);
    assert_eq!(triangles[0], [Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]);
    assert_eq!(triangles[1], [Vec3::X, Vec3::Y, Vec3::Y]);
}

#[test]
fn gltf_strips_fans_and_skipped_modes() {
    let dir = scratch("gltf_strips_fans_and_skipped_modes");
    // Without indices: a strip and a fan over the quad's 4 vertices, and points (skipped).
    let json = quad_gltf(r#"{"byteLength": 60}"#).replace(
        r#""primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]"#,
        r#""primitives": [{"attributes": {"POSITION": 0}, "mode": 5}, {"attributes": {"POSITION": 0}, "mode": 6},
                          {"attributes": {"POSITION": 0}, "mode": 0}]"#,
    );
    let loaded = load_file(&write(&dir, "modes.glb", glb(&json, &quad_buffer()))).expect("loads");
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("Points"), "{}", loaded.warnings[0]);
    let mesh = loaded.scene.nodes().iter().find_map(|n| n.mesh()).expect("a mesh");
    // Strip 0 1 2 / 2 1 3 (odd one flipped), fan 0 1 2 / 0 2 3; one shared vertex array.
    assert_eq!(mesh.triangles(), &[[0, 1, 2], [2, 1, 3], [0, 1, 2], [0, 2, 3]]);
    assert_eq!(mesh.positions().len(), 4);
    assert_eq!(loaded.scene.item_count(), 12);
}

// ---------------------------------------------------------------------------------------------
// Bad input: every case is an error naming the file

#[test]
fn unknown_extension_and_missing_files() {
    let dir = scratch("unknown_extension_and_missing_files");
    assert!(matches!(
        load_err(&write(&dir, "model.stl", "solid")),
        LoadError::UnsupportedExtension { .. }
    ));
    assert!(matches!(
        load_err(&write(&dir, "no_extension", "v 0 0 0")),
        LoadError::UnsupportedExtension { .. }
    ));
    for name in ["absent.obj", "absent.ply", "absent.gltf", "absent.glb"] {
        assert!(matches!(load_err(&dir.join(name)), LoadError::Io { .. }), "{name}");
    }
    std::fs::create_dir_all(dir.join("folder.obj")).expect("folder");
    assert!(matches!(load_err(&dir.join("folder.obj")), LoadError::Io { .. }));
}

#[test]
fn obj_bad_input_names_file_and_line() {
    let dir = scratch("obj_bad_input_names_file_and_line");
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let case = |name: &str, text: &str| load_err(&write(&dir, name, text));

    let e = case("range.obj", &format!("{tri}f 1 2 3\nf 1 2 900\n"));
    assert_index_out_of_range(&e, 900, 3);
    assert!(e.to_string().contains("range.obj line 5"), "{e}");
    assert!(matches!(
        case("zero.obj", &format!("{tri}f 0 1 2\n")),
        LoadError::IndexOutOfRange { index: 0, .. }
    ));
    assert!(matches!(
        case("negative.obj", &format!("{tri}f -4 1 2\n")),
        LoadError::IndexOutOfRange { .. }
    ));

    let e = case("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    assert!(
        matches!(
            e,
            LoadError::NonFinite {
                location: Location::Line(2),
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("coordinate is NaN"), "{e}");
    for (name, text) in [("inf.obj", "v 0 0 0\nv 1 -inf 0\n"), ("overflow.obj", "v 0 0 1e39\n")] {
        assert!(matches!(case(name, text), LoadError::NonFinite { .. }), "{name}");
    }

    // A file whose only face has two corners: that face is skipped, nothing is left.
    let e = case("short_face.obj", &format!("{tri}f 1 2\n"));
    assert!(
        matches!(e, LoadError::Empty { ref reason, .. } if reason.contains("fewer than 3 corners")),
        "{e}"
    );
    // What a cut file looks like: a vertex statement missing its tail.
    for (name, text) in [
        ("short_vertex.obj", "v 0 0 0\nv 1 0\n".to_string()),
        ("lone_sign.obj", format!("{tri}f 1 2 -\n")),
    ] {
        assert!(matches!(case(name, &text), LoadError::Parse { .. }), "{name}");
    }
    assert!(matches!(
        case("bad_number.obj", "v 0 0 zero\n"),
        LoadError::Parse {
            location: Location::Line(1),
            ..
        }
    ));

    assert!(matches!(case("empty.obj", ""), LoadError::Empty { .. }));
    assert!(matches!(case("vertices_only.obj", tri), LoadError::Empty { .. }));
    assert!(matches!(
        case("lines_only.obj", &format!("{tri}l 1 2\n")),
        LoadError::Empty { .. }
    ));
    let garbage: Vec<u8> = (0u32..4096)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let _ = load_file(&write(&dir, "garbage.obj", &garbage))
        .map(|_| ())
        .map_err(|e| {
            assert!(e.to_string().contains("garbage.obj"), "{e}");
        });
}

/// A minimal ascii PLY: `vertex_lines` after a header declaring `vertex_count` and `face_count`.
fn ascii_ply(vertex_count: &str, face_count: &str, body: &str) -> String {
    format!(
        "ply\nformat ascii 1.0\nelement vertex {vertex_count}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {face_count}\nproperty list uchar int vertex_indices\nend_header\n{body}"
    )
}

#[test]
fn ply_bad_input_names_file_and_element() {
    let dir = scratch("ply_bad_input_names_file_and_element");
    let verts = "0 0 0\n1 0 0\n0 1 0\n";
    let case = |name: &str, bytes: &[u8]| load_err(&write(&dir, name, bytes));
    let ascii = |name: &str, v: &str, f: &str, body: &str| load_err(&write(&dir, name, ascii_ply(v, f, body)));

    // Truncated, each encoding.
    assert!(matches!(ascii("cut.ply", "3", "1", verts), LoadError::Truncated { .. }));
    assert!(matches!(
        ascii("cut_vertices.ply", "3", "1", "0 0 0\n1 0 0\n"),
        LoadError::Truncated { .. }
    ));
    for (name, big_endian) in [("cut_le.ply", false), ("cut_be.ply", true)] {
        let full = ply_binary(big_endian, "list uchar int vertex_indices");
        let e = case(name, &full[..full.len() - 3]);
        assert!(matches!(e, LoadError::Truncated { .. }), "{e}");
        assert!(e.to_string().contains("face 2"), "{e}");
    }
    assert!(matches!(
        case("cut_header.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n"),
        LoadError::Truncated { .. }
    ));

    // Element counts that do not match the data.
    let e = ascii("extra_line.ply", "3", "1", &format!("{verts}3 0 1 2\n3 0 1 2\n"));
    assert!(
        matches!(
            e,
            LoadError::CountMismatch {
                location: Location::Line(14),
                ..
            }
        ),
        "{e}"
    );
    let e = ascii("extra_value.ply", "3", "1", "0 0 0\n1 0 0 7\n0 1 0\n3 0 1 2\n");
    assert!(matches!(e, LoadError::CountMismatch { .. }), "{e}");
    assert!(e.to_string().contains("line 11: vertex 1"), "{e}");
    let e = ascii("short_list.ply", "3", "1", &format!("{verts}4 0 1 2\n"));
    assert!(matches!(e, LoadError::CountMismatch { .. }), "{e}");
    let mut trailing = ply_binary(false, "list uchar int vertex_indices");
    trailing.extend([0, 0, 0, 0]);
    assert!(matches!(
        case("trailing.ply", &trailing),
        LoadError::CountMismatch { .. }
    ));

    // Indices and coordinates.
    let e = ascii("range.ply", "3", "1", &format!("{verts}3 0 1 900\n"));
    assert_index_out_of_range(&e, 900, 3);
    assert!(e.to_string().contains("face 0"), "{e}");
    assert!(matches!(
        ascii("negative.ply", "3", "1", &format!("{verts}3 0 -1 2\n")),
        LoadError::IndexOutOfRange { .. }
    ));
    let e = ascii("nan.ply", "3", "1", "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n");
    assert!(matches!(e, LoadError::NonFinite { .. }), "{e}");
    assert!(e.to_string().contains("vertex 1: coordinate is NaN"), "{e}");
    let mut nan_binary = ply_binary(true, "list uchar int vertex_indices");
    let header_len = nan_binary
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("header")
        + 11;
    // Vertex 2's y: after vertices 0 and 1 (21 bytes each), the flags byte and x.
    let y = header_len + 2 * 21 + 1 + 4;
    nan_binary[y..y + 4].copy_from_slice(&f32::INFINITY.to_be_bytes());
    let e = case("inf_be.ply", &nan_binary);
    assert!(e.to_string().ends_with("vertex 2: coordinate is inf"), "{e}");
    assert!(matches!(
        ascii("word.ply", "3", "1", "0 0 zero\n1 0 0\n0 1 0\n3 0 1 2\n"),
        LoadError::Parse { .. }
    ));

    // Absurd counts are refused before anything is allocated.
    let e = ascii("absurd.ply", "1000000000000", "1", &format!("{verts}3 0 1 2\n"));
    assert!(
        matches!(
            e,
            LoadError::AbsurdCount {
                count: 1_000_000_000_000,
                ..
            }
        ),
        "{e}"
    );
    let absurd_faces = ply_binary(false, "list uchar int vertex_indices");
    let text = String::from_utf8_lossy(&absurd_faces).replace("element face 3", "element face 4000000000");
    let e = case("absurd_faces.ply", text.as_bytes());
    assert!(matches!(e, LoadError::AbsurdCount { .. }), "{e}");
    assert!(matches!(
        ascii("overflow_count.ply", "99999999999999999999999", "1", verts),
        LoadError::Parse { .. }
    ));

    // No triangles; wrong structure.
    assert!(matches!(
        ascii("no_faces.ply", "3", "0", verts),
        LoadError::Empty { .. }
    ));
    let points = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
    assert!(matches!(case("points.ply", points.as_bytes()), LoadError::Empty { .. }));
    let no_y = ascii_ply("1", "1", "0 0\n3 0 0 0\n").replace("property float y\n", "");
    assert!(matches!(case("no_y.ply", no_y.as_bytes()), LoadError::Parse { .. }));
    let float_indices = ascii_ply("3", "1", "").replace("list uchar int", "list uchar float");
    assert!(matches!(
        case("float_indices.ply", float_indices.as_bytes()),
        LoadError::Unsupported { .. }
    ));
    assert!(matches!(
        case("not_ply.ply", b"solid cube\nfacet normal 0 0 1\n"),
        LoadError::Parse { .. }
    ));
    assert!(matches!(
        case("empty.ply", b""),
        LoadError::Truncated { .. } | LoadError::Parse { .. }
    ));
}

#[test]
fn gltf_bad_input_names_file_and_part() {
    let dir = scratch("gltf_bad_input_names_file_and_part");
    let good = quad_glb();
    let case = |name: &str, bytes: &[u8]| load_err(&write(&dir, name, bytes));
    let glb_with = |from: &str, to: &str| glb(&quad_gltf(r#"{"byteLength": 60}"#).replace(from, to), &quad_buffer());

    // Truncated GLB and JSON.
    assert!(matches!(
        case("cut.glb", &good[..good.len() - 10]),
        LoadError::Truncated { .. }
    ));
    assert!(matches!(
        case("cut_header.glb", &good[..10]),
        LoadError::Truncated { .. }
    ));
    let json = quad_gltf(r#"{"uri": "quad.bin", "byteLength": 60}"#);
    assert!(matches!(
        case("cut.gltf", &json.as_bytes()[..json.len() / 2]),
        LoadError::Truncated { .. }
    ));
    assert!(matches!(
        case("empty.gltf", b""),
        LoadError::Truncated { .. } | LoadError::Parse { .. }
    ));

    // Buffers: missing file (named with the document), too short, missing BIN chunk.
    let e = case("missing_bin.gltf", json.as_bytes());
    assert!(matches!(e, LoadError::Buffer { .. }), "{e}");
    assert!(e.to_string().contains("quad.bin"), "{e}");
    write(&dir, "short.bin", &quad_buffer()[..40]);
    let short = quad_gltf(r#"{"uri": "short.bin", "byteLength": 60}"#);
    assert!(matches!(
        case("short_bin.gltf", short.as_bytes()),
        LoadError::Buffer { .. }
    ));
    let no_bin_chunk = glb(&quad_gltf(r#"{"byteLength": 60}"#), &[]);
    let no_bin_chunk = &no_bin_chunk[..no_bin_chunk.len() - 8];
    let mut no_bin_chunk = no_bin_chunk.to_vec();
    let total = no_bin_chunk.len() as u32;
    no_bin_chunk[8..12].copy_from_slice(&total.to_le_bytes());
    assert!(matches!(
        case("no_bin_chunk.glb", &no_bin_chunk),
        LoadError::Buffer { .. }
    ));
    let bad_base64 = quad_gltf(r#"{"uri": "data:application/octet-stream;base64,@@@@", "byteLength": 60}"#);
    assert!(matches!(
        case("bad_base64.gltf", bad_base64.as_bytes()),
        LoadError::Buffer { .. }
    ));

    // Accessors past their views, views past their buffers, absurd counts.
    let e = case("long_accessor.glb", &glb_with(r#""count": 6"#, r#""count": 7"#));
    assert!(matches!(e, LoadError::CountMismatch { .. }), "{e}");
    assert!(e.to_string().contains("mesh 0 'quad' primitive 0"), "{e}");
    assert!(matches!(
        case(
            "long_view.glb",
            &glb_with(r#""byteLength": 12}"#, r#""byteLength": 16}"#)
        ),
        LoadError::CountMismatch { .. }
    ));
    assert!(matches!(
        case("absurd.glb", &glb_with(r#""count": 4,"#, r#""count": 1000000000000,"#)),
        LoadError::AbsurdCount { .. }
    ));
    // Without a view an accessor must be sparse; its zeros would still cost memory.
    let sparse_absurd = glb_with(
        r#""bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3","#,
        r#""componentType": 5126, "count": 1000000000000, "type": "VEC3",
            "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5123}, "values": {"bufferView": 0}},"#,
    );
    assert!(matches!(
        case("absurd_sparse.glb", &sparse_absurd),
        LoadError::AbsurdCount { .. }
    ));
    let no_view = glb_with(
        r#""bufferView": 0, "componentType": 5126, "count": 4"#,
        r#""componentType": 5126, "count": 4"#,
    );
    assert!(matches!(case("no_view.glb", &no_view), LoadError::Parse { .. }));
    let sparse_past = glb_with(
        r#""bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3","#,
        r#""bufferView": 0, "componentType": 5126, "count": 2, "type": "VEC3",
            "sparse": {"count": 3, "indices": {"bufferView": 1, "componentType": 5123}, "values": {"bufferView": 0}},"#,
    );
    let e = case("sparse_past.glb", &sparse_past);
    assert!(e.to_string().contains("sparse index 2"), "{e}");
    let missing_position = glb_with(r#""POSITION": 0"#, r#""POSITION": 90"#);
    assert!(matches!(
        case("missing_position.glb", &missing_position),
        LoadError::Parse { .. }
    ));
    assert!(matches!(
        case("empty_accessor.glb", &glb_with(r#""count": 6"#, r#""count": 0"#)),
        LoadError::Empty { .. }
    ));
    assert!(matches!(
        case(
            "stride.glb",
            &glb_with(
                r#""byteOffset": 0, "byteLength": 48}"#,
                r#""byteOffset": 0, "byteLength": 48, "byteStride": 8}"#
            )
        ),
        LoadError::Parse { .. }
    ));
    assert!(matches!(
        case(
            "float_indices.glb",
            &glb_with(r#""componentType": 5123"#, r#""componentType": 5126"#)
        ),
        LoadError::Unsupported { .. }
    ));

    // Indices and coordinates.
    let mut bad_index = quad_buffer();
    bad_index[48 + 10..48 + 12].copy_from_slice(&9u16.to_le_bytes());
    let e = case("range.glb", &glb(&quad_gltf(r#"{"byteLength": 60}"#), &bad_index));
    assert_index_out_of_range(&e, 9, 4);
    let mut nan = quad_buffer();
    nan[16..20].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = case("nan.glb", &glb(&quad_gltf(r#"{"byteLength": 60}"#), &nan));
    assert!(matches!(e, LoadError::NonFinite { .. }), "{e}");
    assert!(e.to_string().contains("vertex 1"), "{e}");

    // Structure: invalid references, no mesh, cycles, singular transforms.
    assert!(matches!(
        case(
            "bad_ref.glb",
            &glb_with(r#""mesh": 0, "translation""#, r#""mesh": 5, "translation""#)
        ),
        LoadError::Parse { .. }
    ));
    assert!(matches!(
        case("no_nodes.glb", &glb_with(r#""nodes": [0]"#, r#""nodes": []"#)),
        LoadError::Empty { .. }
    ));
    let e = case(
        "cycle.glb",
        &glb_with(
            r#"{"mesh": 0, "translation": [2, 0, 0]}"#,
            r#"{"mesh": 0, "children": [0]}"#,
        ),
    );
    assert!(e.to_string().contains("cycle"), "{e}");
    let hidden = glb_with(r#""translation": [2, 0, 0]"#, r#""scale": [0, 0, 0]"#);
    let loaded = load_ok(&write(&dir, "hidden.glb", hidden));
    assert_eq!(loaded.scene.item_count(), 4);
    assert!(loaded.warnings[0].contains("singular"), "{:?}", loaded.warnings);
    assert!(matches!(
        case("not_json.gltf", b"solid cube"),
        LoadError::Parse {
            location: Location::Line(1),
            ..
        }
    ));
}

// ---------------------------------------------------------------------------------------------
// Real-world files that other readers accept: loaded, with one warning per kind

#[test]
fn obj_faces_of_one_and_two_corners_are_skipped_with_one_warning() {
    let dir = scratch("obj_faces_of_one_and_two_corners_are_skipped_with_one_warning");
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 2\nf 1 3 4\nf 4\nf 2 3 4 1\n";
    let path = write(&dir, "short.obj", text);
    let loaded = load_ok(&path);
    assert_eq!(loaded.scene.item_count(), 1 + 1 + 2);
    assert_eq!(loaded.scene.bounds().max, Vec3::new(1.0, 1.0, 0.0));
    assert_eq!(
        loaded.warnings,
        [format!(
            "{}: 2 faces with fewer than 3 corners skipped (first at line 6)",
            path.display()
        )]
    );
}

#[test]
fn obj_index_zero_is_still_an_error_naming_file_and_line() {
    let dir = scratch("obj_index_zero_is_still_an_error_naming_file_and_line");
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    // In a whole face, and in a face too short to be drawn.
    for (name, face) in [("zero.obj", "f 1 0 2"), ("zero_short.obj", "f 0 1")] {
        let path = write(&dir, name, format!("{tri}f 1 2 3\n{face}\n"));
        let e = load_err(&path);
        assert_index_out_of_range(&e, 0, 3);
        assert!(e.to_string().starts_with(&format!("{} line 5:", path.display())), "{e}");
    }
}

#[test]
fn ply_bare_text_header_line_is_a_comment_with_one_warning() {
    let dir = scratch("ply_bare_text_header_line_is_a_comment_with_one_warning");
    let note = "Exported by ScanTool 2.1\n";
    let insert_note = |bytes: &[u8]| {
        // After `ply\nformat ...\n`: the third line.
        let second_end = bytes
            .iter()
            .enumerate()
            .filter(|(_, &b)| b == b'\n')
            .nth(1)
            .expect("two lines")
            .0;
        [&bytes[..=second_end], note.as_bytes(), &bytes[second_end + 1..]].concat()
    };
    let ascii = insert_note(PLY_ASCII.as_bytes());
    let binary = insert_note(&ply_binary(false, "list uchar int vertex_indices"));
    for (name, bytes) in [("note_ascii.ply", ascii), ("note_le.ply", binary)] {
        let path = write(&dir, name, bytes);
        let loaded = load_ok(&path);
        assert_eq!(loaded.scene.item_count(), 4, "{name}");
        assert_eq!(loaded.scene.bounds().max, Vec3::new(1.0, 1.0, 2.0), "{name}");
        assert_eq!(
            loaded.warnings,
            [format!(
                "{} line 3: a header line that is not a PLY keyword read as a comment: 'Exported by ScanTool 2.1'",
                path.display()
            )],
            "{name}"
        );
    }
    // Lines after the note keep their numbers in errors.
    let bad = ascii_ply("3", "1", "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").replacen(
        "format ascii 1.0\n",
        "format ascii 1.0\nnote\n",
        1,
    );
    let e = load_err(&write(&dir, "bad_index.ply", bad));
    assert!(e.to_string().contains("line 14: face 0"), "{e}");
    // A misspelt keyword is no note: still an error with its line.
    let typo = PLY_ASCII.replacen("element face", "elemnt face", 1);
    let e = load_err(&write(&dir, "typo.ply", typo));
    assert!(e.to_string().contains("line 10, column 1: bad header"), "{e}");
}

/// The component type codes of glTF accessors.
const GLTF_UNSIGNED_BYTE: u32 = 5121;
const GLTF_SHORT: u32 = 5122;
const GLTF_UNSIGNED_SHORT: u32 = 5123;

/// A document requiring `KHR_mesh_quantization` whose one node (`node`: its JSON properties
/// besides the mesh) holds a quad with integer positions of `component_type`, padded to a
/// stride of 4 bytes, and its JSON buffer `buffer`; and the buffer's bytes.
fn quantized_gltf(
    component_type: u32,
    normalized: bool,
    corners: [[i32; 3]; 4],
    node: &str,
    buffer: &str,
) -> (String, Vec<u8>) {
    let size = if component_type == GLTF_UNSIGNED_BYTE || component_type == 5120 {
        1
    } else {
        2
    };
    // §3.6.2.4: each vertex attribute element starts on a 4-byte boundary.
    let stride = 4 * size;
    let mut bin = Vec::new();
    for corner in corners {
        for c in corner {
            match size {
                1 => bin.push(c as u8),
                _ => bin.extend((c as u16).to_le_bytes()),
            }
        }
        bin.resize(bin.len() + stride - 3 * size, 0);
    }
    let positions_len = bin.len();
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend(i.to_le_bytes());
    }
    let min: Vec<i32> = (0..3).map(|k| corners.iter().map(|c| c[k]).min().unwrap()).collect();
    let max: Vec<i32> = (0..3).map(|k| corners.iter().map(|c| c[k]).max().unwrap()).collect();
    let buffer = buffer.replace("LENGTH", &bin.len().to_string());
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_mesh_quantization"],
  "extensionsRequired": ["KHR_mesh_quantization"],
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0, {node}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
  "buffers": [{buffer}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {positions_len}, "byteStride": {stride}, "target": 34962}},
    {{"buffer": 0, "byteOffset": {positions_len}, "byteLength": 12, "target": 34963}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": {component_type}, "normalized": {normalized}, "count": 4, "type": "VEC3",
      "min": {min:?}, "max": {max:?}}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
    );
    (json, bin)
}

/// Asserts that `loaded` holds the two triangles of the quad `corners` (world space) and
/// their bounds, to within `tolerance` (the node transform rounds).
fn check_quantized_quad(loaded: &LoadedScene, corners: [Vec3; 4], tolerance: f32) {
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_eq!(loaded.scene.item_count(), 2);
    let triangles = world_triangles(&loaded.scene);
    let expected = [
        [corners[0], corners[1], corners[2]],
        [corners[0], corners[2], corners[3]],
    ];
    for (got, want) in triangles.iter().flatten().zip(expected.iter().flatten()) {
        assert!(got.abs_diff_eq(*want, tolerance), "{got} != {want}");
    }
    let min = corners.iter().copied().reduce(Vec3::min).unwrap();
    let max = corners.iter().copied().reduce(Vec3::max).unwrap();
    let bounds = loaded.scene.bounds();
    assert!(
        bounds.min.abs_diff_eq(min, tolerance) && bounds.max.abs_diff_eq(max, tolerance),
        "{bounds:?}"
    );
}

#[test]
fn gltf_quantized_positions_load_with_their_node_transform() {
    let dir = scratch("gltf_quantized_positions_load_with_their_node_transform");
    // Normalized SHORT: c / 32767, and -32768 clamps to -1 (glTF §3.6.2). The node scales by 2
    // and moves by 10 along x, as a quantizer writes it.
    let corners = [[0, 0, 0], [32767, 0, -32768], [32767, 32767, -32767], [0, 32767, 16384]];
    let node = r#""translation": [10, 0, 0], "scale": [2, 2, 2]"#;
    let world = |c: [i32; 3]| {
        let local = Vec3::from_array(c.map(|v| (v as f32 / 32767.0).max(-1.0)));
        local * 2.0 + Vec3::new(10.0, 0.0, 0.0)
    };
    let expected = corners.map(world);
    assert_eq!(expected[1], Vec3::new(12.0, 0.0, -2.0));
    let (json, bin) = quantized_gltf(
        GLTF_SHORT,
        true,
        corners,
        node,
        r#"{"uri": "short.bin", "byteLength": LENGTH}"#,
    );
    write(&dir, "short.bin", &bin);
    check_quantized_quad(&load_ok(&write(&dir, "short.gltf", json)), expected, 1e-6);

    // Plain UNSIGNED_SHORT: the values themselves, scaled by the node's matrix (1/1000), as GLB.
    let corners = [[0, 0, 0], [1000, 0, 0], [1000, 500, 65535], [0, 500, 1]];
    let node = r#""matrix": [0.001,0,0,0, 0,0.001,0,0, 0,0,0.001,0, 0,0,0,1]"#;
    let expected = corners.map(|c| Vec3::from_array(c.map(|v| v as f32)) * 0.001);
    let (json, bin) = quantized_gltf(GLTF_UNSIGNED_SHORT, false, corners, node, r#"{"byteLength": LENGTH}"#);
    let loaded = load_ok(&write(&dir, "ushort.glb", glb(&json, &bin)));
    check_quantized_quad(&loaded, expected, 1e-5);
    assert_eq!(loaded.scene.bounds().max.z, 65535.0 * 0.001);

    // Normalized UNSIGNED_BYTE, embedded: c / 255.
    let corners = [[0, 0, 0], [255, 0, 0], [255, 255, 51], [0, 255, 0]];
    let expected = corners.map(|c| Vec3::from_array(c.map(|v| v as f32 / 255.0)));
    let (json, bin) = quantized_gltf(GLTF_UNSIGNED_BYTE, true, corners, r#""name": "bytes""#, "BUFFER");
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let json = json.replace("BUFFER", &format!(r#"{{"uri": "{uri}", "byteLength": {}}}"#, bin.len()));
    check_quantized_quad(&load_ok(&write(&dir, "bytes.gltf", json)), expected, 0.0);

    // Another required extension is still refused, naming it.
    let (json, bin) = quantized_gltf(GLTF_SHORT, true, corners, node, r#"{"byteLength": LENGTH}"#);
    let json = json.replace(
        r#""extensionsRequired": ["KHR_mesh_quantization"]"#,
        r#""extensionsRequired": ["KHR_mesh_quantization", "KHR_draco_mesh_compression"]"#,
    );
    let e = load_err(&write(&dir, "draco.glb", glb(&json, &bin)));
    assert!(
        matches!(e, LoadError::Parse { .. }) && e.to_string().contains("KHR_draco_mesh_compression"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// Robustness: prefixes and single-byte corruptions of valid files never panic

/// Loads `bytes` as the file `name` in `dir` (from memory: thousands of cases): an error must
/// name the file; never a panic.
fn load_quietly(dir: &Path, name: &str, bytes: &[u8]) -> Option<LoadedScene> {
    match load_bytes(&dir.join(name), bytes) {
        Ok(loaded) => Some(loaded),
        Err(e) => {
            assert!(e.to_string().contains(name), "error '{e}' does not name {name}");
            None
        }
    }
}

#[test]
fn every_prefix_fails_cleanly() {
    let dir = scratch("every_prefix_fails_cleanly");
    write(&dir, "quad.bin", quad_buffer());
    let samples: Vec<(&str, Vec<u8>, bool)> = vec![
        // (name, bytes, whether every proper prefix must be an error)
        ("prefix.obj", OBJ_WITH_MATERIALS.as_bytes().to_vec(), false),
        ("prefix_ascii.ply", PLY_ASCII.as_bytes().to_vec(), false),
        (
            "prefix_le.ply",
            ply_binary(false, "list uchar int vertex_indices"),
            true,
        ),
        (
            "prefix_be.ply",
            ply_binary(true, "list uchar ushort vertex_indices"),
            true,
        ),
        ("prefix.glb", quad_glb(), true),
        (
            "prefix.gltf",
            quad_gltf(r#"{"uri": "quad.bin", "byteLength": 60}"#).into_bytes(),
            true,
        ),
    ];
    for (name, bytes, strict) in samples {
        for len in 0..bytes.len() {
            let loaded = load_quietly(&dir, name, &bytes[..len]);
            assert!(!strict || loaded.is_none(), "{name}: a prefix of {len} bytes loaded");
        }
        assert!(
            load_quietly(&dir, name, &bytes).is_some(),
            "{name}: the whole file must load"
        );
    }
}

#[test]
fn single_byte_corruptions_never_panic() {
    let dir = scratch("single_byte_corruptions_never_panic");
    let samples: Vec<(&str, Vec<u8>)> = vec![
        ("flip.glb", quad_glb()),
        ("flip_le.ply", ply_binary(false, "list uchar int vertex_indices")),
        ("flip_be.ply", ply_binary(true, "list uchar uint vertex_indices")),
        ("flip_ascii.ply", PLY_ASCII.as_bytes().to_vec()),
        ("flip.obj", OBJ_POLYGONS.as_bytes().to_vec()),
    ];
    for (name, bytes) in samples {
        for index in 0..bytes.len() {
            for value in [0x00, 0x80, 0xff, b'0', b'9', b'-', b'"', b'\n'] {
                let mut corrupted = bytes.clone();
                corrupted[index] = value;
                load_quietly(&dir, name, &corrupted);
            }
        }
        // A few thousand seeded multi-byte corruptions.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..2000 {
            let mut corrupted = bytes.clone();
            for _ in 0..1 + next() % 4 {
                let index = (next() % corrupted.len() as u64) as usize;
                corrupted[index] = next() as u8;
            }
            load_quietly(&dir, name, &corrupted);
        }
    }
}

/// Found by the `gltf` fuzz target: a data URI holding an escaped line break (`\n` in the JSON)
/// made a two-line error. Names and URIs come from the file; errors escape their line breaks.
#[test]
fn gltf_line_breaks_in_uris_and_names_stay_escaped() {
    let dir = scratch("gltf_line_breaks_in_uris_and_names_stay_escaped");
    let uri =
        r#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "data:a-stream;base64,A\nSCALAR", "byteLength": 1}]}"#;
    let e = load_err(&write(&dir, "uri.gltf", uri)).to_string();
    assert!(!e.contains('\n') && e.contains(r"base64,A\nSCALAR"), "{e}");
    // A mesh named with a line break whose index is out of range.
    let name = format!(
        r#"{{"asset": {{"version": "2.0"}},
            "buffers": [{{"uri": "data:application/octet-stream;base64,{}", "byteLength": 42}}],
            "bufferViews": [{{"buffer": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 6}}],
            "accessors": [
              {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
              {{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}}],
            "meshes": [{{"name": "two\nlines", "primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
            "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]}}"#,
        base64(&{
            let mut bytes = Vec::new();
            for c in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
                bytes.extend(c.to_le_bytes());
            }
            for i in [0u16, 1, 7, 0, 0, 0] {
                bytes.extend(i.to_le_bytes());
            }
            bytes
        })
    );
    let e = load_err(&write(&dir, "name.gltf", name));
    assert!(matches!(e, LoadError::IndexOutOfRange { index: 7, .. }), "{e}");
    assert!(e.to_string().contains(r"'two\nlines'"), "{e}");
}
