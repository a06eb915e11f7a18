//! Writes the seed corpus of the loaders' fuzz targets.
//!
//! `fuzz-seeds OUT [DIR...]`: every model file found (recursively) in the `DIR`s goes to
//! `OUT/<target>/` in the layout [`occult_fuzz::Target`] reads (a PLY without its first two
//! lines, in the folder of its encoding; an OBJ with its `.mtl` as companion; a `.gltf` with its
//! `.bin`), and each model that loads also gives small excerpts (its first triangles) written in
//! every format, so that each target starts from valid files of its own kind whatever the
//! inputs were. Files larger than `--max-bytes` (default 65536, the campaign's `-max_len`) are
//! skipped whole, kept only as excerpts.

use std::path::{Path, PathBuf};

use occult_core::Vec3;
use occult_fuzz::{with_companion, Target};
use occult_scenes::load::load_file;
use occult_scenes::save::glb_container as glb;

/// Triangles kept in an excerpt.
const EXCERPT_TRIANGLES: [usize; 2] = [4, 200];

fn main() {
    if let Err(message) = run() {
        eprintln!("fuzz-seeds: {message}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut max_bytes = 65536usize;
    if let Some(at) = args.iter().position(|a| a == "--max-bytes") {
        let value = args.get(at + 1).ok_or("--max-bytes needs a value")?;
        max_bytes = value.parse().map_err(|_| format!("bad --max-bytes '{value}'"))?;
        args.drain(at..at + 2);
    }
    let Some((out, dirs)) = args.split_first() else {
        return Err("usage: fuzz-seeds OUT [--max-bytes N] [DIR...]".into());
    };
    let out = PathBuf::from(out);
    for target in Target::ALL {
        std::fs::create_dir_all(out.join(target.name())).map_err(|e| format!("{}: {e}", out.display()))?;
    }
    let mut files = Vec::new();
    for dir in dirs {
        walk(Path::new(dir), &mut files);
    }
    files.sort();
    let mut written = 0usize;
    let mut seeds = Seeds {
        out,
        written: &mut written,
    };
    for file in &files {
        seeds.model(file, max_bytes);
    }
    seeds.synthetic();
    println!("fuzz-seeds: {written} seeds from {} model files", files.len());
    Ok(())
}

fn walk(dir: &Path, files: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            walk(&path, files);
        } else if matches!(extension(&path).as_str(), "obj" | "ply" | "gltf" | "glb") {
            files.push(path);
        }
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .map_or_else(String::new, |e| e.to_string_lossy().to_ascii_lowercase())
}

struct Seeds<'w> {
    out: PathBuf,
    written: &'w mut usize,
}

impl Seeds<'_> {
    fn write(&mut self, target: Target, name: &str, bytes: &[u8]) {
        let name: String = name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let path = self.out.join(target.name()).join(name);
        match std::fs::write(&path, bytes) {
            Ok(()) => *self.written += 1,
            Err(e) => eprintln!("fuzz-seeds: {}: {e}", path.display()),
        }
    }

    /// The file itself (when small enough) and excerpts of what it loads to.
    fn model(&mut self, file: &Path, max_bytes: usize) {
        let Ok(bytes) = std::fs::read(file) else { return };
        let stem = file.to_string_lossy().replace('/', "_");
        if bytes.len() <= max_bytes {
            match extension(file).as_str() {
                "obj" => {
                    self.write(Target::Obj, &stem, &bytes);
                    if let Some(mtl) = sibling_mtl(file) {
                        let mut obj = b"mtllib m.mtl\n".to_vec();
                        obj.extend_from_slice(&bytes);
                        self.write(Target::Obj, &format!("{stem}+mtl"), &with_companion(&obj, &mtl));
                    }
                }
                "ply" => {
                    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(200)]).into_owned();
                    let target = if text.contains("format ascii") {
                        Target::PlyAscii
                    } else if text.contains("format binary_little_endian") {
                        Target::PlyBinaryLe
                    } else {
                        Target::PlyBinaryBe
                    };
                    self.write(target, &stem, strip_two_lines(&bytes));
                }
                "gltf" => match sibling_bin(file, &bytes) {
                    Some((name, bin)) => {
                        let json = String::from_utf8_lossy(&bytes).replace(&name, "b.bin");
                        self.write(Target::Gltf, &stem, &with_companion(json.as_bytes(), &bin));
                    }
                    None => self.write(Target::Gltf, &stem, &bytes),
                },
                _ => self.write(Target::Gltf, &stem, &bytes),
            }
        }
        let Ok(loaded) = load_file(file) else { return };
        let Ok(mesh) = loaded.scene.flatten(u64::MAX) else {
            return;
        };
        for count in EXCERPT_TRIANGLES {
            let triangles: Vec<[Vec3; 3]> = (0..mesh.triangle_count().min(count))
                .map(|t| mesh.triangle_positions(t))
                .collect();
            self.excerpts(&format!("{stem}-{count}"), &triangles);
        }
    }

    /// `triangles` written in every format.
    fn excerpts(&mut self, name: &str, triangles: &[[Vec3; 3]]) {
        let (positions, indices) = indexed(triangles);
        self.write(Target::Obj, &format!("{name}.obj"), &obj_text(&positions, &indices));
        for target in [Target::PlyAscii, Target::PlyBinaryLe, Target::PlyBinaryBe] {
            let ply = ply_bytes(target, &positions, &indices);
            self.write(target, &format!("{name}.ply"), strip_two_lines(&ply));
        }
        let bin = gltf_bin(&positions, &indices);
        let json = gltf_json(&positions, indices.len(), bin.len(), Some("b.bin"));
        self.write(
            Target::Gltf,
            &format!("{name}.gltf"),
            &with_companion(json.as_bytes(), &bin),
        );
        let json = gltf_json(&positions, indices.len(), bin.len(), None);
        self.write(Target::Gltf, &format!("{name}.glb"), &glb(&json, &bin));
        for (filter, mode) in [("NONE", "TRIANGLES"), ("EXPONENTIAL", "INDICES")] {
            if let Some(compressed) = meshopt_glb(&positions, &indices, filter, mode) {
                self.write(Target::Gltf, &format!("{name}-meshopt-{filter}.glb"), &compressed);
            }
        }
    }

    /// Small files that reach branches the real models do not.
    fn synthetic(&mut self) {
        let quad = [[Vec3::ZERO, Vec3::X, Vec3::ONE], [Vec3::ZERO, Vec3::ONE, Vec3::Y]];
        self.excerpts("quad", &quad);
        let obj = b"mtllib m.mtl\no a\nusemtl red\nv 0 0 0\nv 1 0 0 1\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
f 1/1/1 2/1/1 3/1/1 4/1/1\ng b\nusemtl blue\nf -4 -3 -2\nf 1 2\nl 1 2\np 3\ns off\n";
        let mtl = b"newmtl red\nKd 1 0 0\nmap_Kd t.png\nnewmtl blue\nKd 0.2\nmap_Ka -s 1 1 1 gone.png\nbump x.png\n";
        self.write(Target::Obj, "synthetic-materials.obj", &with_companion(obj, mtl));
        let strips = b"comment strips\nobj_info scanner\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nproperty uchar intensity\nelement tristrips 1\nproperty list int int vertex_indices\n\
a bare text line\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n1 1 0 4\n6 0 1 2 -1 1 3\n";
        self.write(Target::PlyAscii, "synthetic-strips.ply", strips);
    }
}

/// The companion `.mtl` of an OBJ: the first `.mtl` in its folder.
fn sibling_mtl(file: &Path) -> Option<Vec<u8>> {
    let dir = file.parent()?;
    let mut mtls: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .filter(|p| extension(p) == "mtl")
        .collect();
    mtls.sort();
    std::fs::read(mtls.first()?).ok()
}

/// The first `.bin` a `.gltf` names (by file name) that exists beside it.
fn sibling_bin(file: &Path, json: &[u8]) -> Option<(String, Vec<u8>)> {
    let text = String::from_utf8_lossy(json);
    let dir = file.parent()?;
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if extension(&entry.path()) == "bin" && text.contains(&format!("\"{name}\"")) {
            return Some((name, std::fs::read(entry.path()).ok()?));
        }
    }
    None
}

fn strip_two_lines(bytes: &[u8]) -> &[u8] {
    let mut rest = bytes;
    for _ in 0..2 {
        match rest.iter().position(|&b| b == b'\n') {
            Some(at) => rest = &rest[at + 1..],
            None => return rest,
        }
    }
    rest
}

/// Triangles as shared positions and indices (vertices merged when bit-equal).
fn indexed(triangles: &[[Vec3; 3]]) -> (Vec<Vec3>, Vec<u32>) {
    let mut positions: Vec<Vec3> = Vec::new();
    let mut index_of = std::collections::HashMap::new();
    let mut indices = Vec::new();
    for corner in triangles.iter().flatten() {
        let key = corner.to_array().map(f32::to_bits);
        let index = *index_of.entry(key).or_insert_with(|| {
            positions.push(*corner);
            positions.len() as u32 - 1
        });
        indices.push(index);
    }
    (positions, indices)
}

fn obj_text(positions: &[Vec3], indices: &[u32]) -> Vec<u8> {
    let mut text = String::from("# excerpt\no excerpt\n");
    for p in positions {
        text.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
    }
    for t in indices.chunks_exact(3) {
        text.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    text.into_bytes()
}

fn ply_bytes(target: Target, positions: &[Vec3], indices: &[u32]) -> Vec<u8> {
    let format = target.ply_format().unwrap_or("ascii");
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment excerpt\nelement vertex {}\nproperty float x\nproperty float y\n\
property float z\nproperty uchar red\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        positions.len(),
        indices.len() / 3
    )
    .into_bytes();
    let big = target == Target::PlyBinaryBe;
    let f32_bytes = |v: f32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
    let u32_bytes = |v: u32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
    for p in positions {
        if target == Target::PlyAscii {
            out.extend_from_slice(format!("{} {} {} 7\n", p.x, p.y, p.z).as_bytes());
        } else {
            for v in p.to_array() {
                out.extend_from_slice(&f32_bytes(v));
            }
            out.push(7);
        }
    }
    for t in indices.chunks_exact(3) {
        if target == Target::PlyAscii {
            out.extend_from_slice(format!("3 {} {} {}\n", t[0], t[1], t[2]).as_bytes());
        } else {
            out.push(3);
            for &i in t {
                out.extend_from_slice(&u32_bytes(i));
            }
        }
    }
    out
}

/// Positions (f32 × 3) then indices (u32), the layout [`gltf_json`] describes.
fn gltf_bin(positions: &[Vec3], indices: &[u32]) -> Vec<u8> {
    let mut bin: Vec<u8> = positions
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    bin
}

fn gltf_json(positions: &[Vec3], index_count: usize, bin_len: usize, uri: Option<&str>) -> String {
    let (min, max) = bounds(positions);
    let position_bytes = positions.len() * 12;
    let uri = uri.map_or_else(String::new, |u| format!("\"uri\":\"{u}\","));
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
"nodes":[{{"mesh":0}},{{"mesh":0,"translation":[2,0,0],"children":[2]}},{{"mesh":0,"scale":[1,2,1]}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"material":0}}]}}],
"materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[1,0.5,0,1]}}}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},
{{"bufferView":1,"componentType":5125,"count":{index_count},"type":"SCALAR"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{position_bytes}}},{{"buffer":0,"byteOffset":{position_bytes},"byteLength":{}}}],
"buffers":[{{{uri}"byteLength":{bin_len}}}]}}"#,
        positions.len(),
        min.x,
        min.y,
        min.z,
        max.x,
        max.y,
        max.z,
        index_count * 4,
    )
}

/// A GLB whose positions (f32 × 3, `filter` NONE or EXPONENTIAL) and u32 indices (`mode`
/// TRIANGLES or INDICES) are `EXT_meshopt_compression` views over a fallback buffer.
fn meshopt_glb(positions: &[Vec3], indices: &[u32], filter: &str, mode: &str) -> Option<Vec<u8>> {
    let floats: Vec<[f32; 3]> = positions.iter().map(|p| p.to_array()).collect();
    let position_bytes = if filter == "EXPONENTIAL" {
        let encoded = meshopt::encode_filter_exp(&floats, 16, meshopt::EncodeExpMode::Separate);
        meshopt::encode_vertex_buffer(&encoded).ok()?
    } else {
        meshopt::encode_vertex_buffer(&floats).ok()?
    };
    let index_bytes = if mode == "TRIANGLES" {
        meshopt::encode_index_buffer(indices, positions.len()).ok()?
    } else {
        meshopt::encode_index_sequence(indices, positions.len()).ok()?
    };
    let mut bin = position_bytes.clone();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let index_offset = bin.len();
    bin.extend_from_slice(&index_bytes);
    let (count, index_count) = (positions.len(), indices.len());
    let (min, max) = bounds(positions);
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["EXT_meshopt_compression"],"extensionsRequired":["EXT_meshopt_compression"],
"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
"buffers":[{{"byteLength":{}}},{{"byteLength":{},"extensions":{{"EXT_meshopt_compression":{{"fallback":true}}}}}}],
"bufferViews":[{{"buffer":1,"byteLength":{},"byteStride":12,"extensions":{{"EXT_meshopt_compression":{{"buffer":0,"byteLength":{},"byteStride":12,"count":{count},"mode":"ATTRIBUTES","filter":"{filter}"}}}}}},
{{"buffer":1,"byteOffset":{},"byteLength":{},"extensions":{{"EXT_meshopt_compression":{{"buffer":0,"byteOffset":{index_offset},"byteLength":{},"byteStride":4,"count":{index_count},"mode":"{mode}"}}}}}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":{count},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},{{"bufferView":1,"componentType":5125,"count":{index_count},"type":"SCALAR"}}]}}"#,
        bin.len(),
        count * 12 + index_count * 4,
        count * 12,
        position_bytes.len(),
        count * 12,
        index_count * 4,
        index_bytes.len(),
        min.x,
        min.y,
        min.z,
        max.x,
        max.y,
        max.z,
    );
    Some(glb(&json, &bin))
}

fn bounds(positions: &[Vec3]) -> (Vec3, Vec3) {
    positions
        .iter()
        .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        })
}
