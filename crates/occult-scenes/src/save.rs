//! Writes a mesh as the files [`crate::load`] reads: OBJ, PLY (ascii, binary little- and
//! big-endian) and GLB. For round-trip tests, load benchmarks and fuzz seeds: positions and
//! triangles only, no colors, no hierarchy.
//!
//! ```
//! use occult_core::{Mesh, Vec3};
//! use occult_scenes::load::load_bytes;
//! use occult_scenes::save::{ply_bytes, PlyEncoding};
//! use std::path::Path;
//!
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])?;
//! let ply = ply_bytes(&mesh, PlyEncoding::BinaryBigEndian);
//! assert_eq!(load_bytes(Path::new("t.ply"), &ply)?.scene.item_count(), 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt::Write as _;

use occult_core::{Mesh, Vec3};

/// The three PLY encodings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyEncoding {
    /// Text.
    Ascii,
    /// Binary, little-endian.
    BinaryLittleEndian,
    /// Binary, big-endian.
    BinaryBigEndian,
}

impl PlyEncoding {
    /// The word of the `format` header line.
    pub fn name(self) -> &'static str {
        match self {
            PlyEncoding::Ascii => "ascii",
            PlyEncoding::BinaryLittleEndian => "binary_little_endian",
            PlyEncoding::BinaryBigEndian => "binary_big_endian",
        }
    }
}

/// The mesh as a Wavefront OBJ: `v x y z` lines (shortest round-trip decimal), then
/// `f a b c` (1-based).
pub fn obj_bytes(mesh: &Mesh) -> Vec<u8> {
    let mut text = String::with_capacity(mesh.positions().len() * 32 + mesh.triangle_count() * 24);
    for p in mesh.positions() {
        // Writing to a String cannot fail.
        let _ = writeln!(text, "v {} {} {}", p.x, p.y, p.z);
    }
    for t in mesh.triangles() {
        let _ = writeln!(text, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    text.into_bytes()
}

/// The mesh as a PLY of `encoding`: `vertex` (`float x y z`) and `face`
/// (`list uchar int vertex_indices`).
pub fn ply_bytes(mesh: &Mesh, encoding: PlyEncoding) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat {} 1.0\ncomment written by occult\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        encoding.name(),
        mesh.positions().len(),
        mesh.triangle_count()
    )
    .into_bytes();
    let big = encoding == PlyEncoding::BinaryBigEndian;
    match encoding {
        PlyEncoding::Ascii => {
            let mut text = String::new();
            for p in mesh.positions() {
                let _ = writeln!(text, "{} {} {}", p.x, p.y, p.z);
            }
            for t in mesh.triangles() {
                let _ = writeln!(text, "3 {} {} {}", t[0], t[1], t[2]);
            }
            out.extend_from_slice(text.as_bytes());
        }
        PlyEncoding::BinaryLittleEndian | PlyEncoding::BinaryBigEndian => {
            out.reserve(mesh.positions().len() * 12 + mesh.triangle_count() * 13);
            for p in mesh.positions() {
                for v in p.to_array() {
                    out.extend_from_slice(&if big { v.to_be_bytes() } else { v.to_le_bytes() });
                }
            }
            for t in mesh.triangles() {
                out.push(3);
                for &i in t {
                    out.extend_from_slice(&if big { i.to_be_bytes() } else { i.to_le_bytes() });
                }
            }
        }
    }
    out
}

/// The mesh as a GLB: one node, one mesh, one triangle primitive with `FLOAT` positions and
/// `UNSIGNED_INT` indices in the binary chunk.
pub fn glb_bytes(mesh: &Mesh) -> Vec<u8> {
    let (json, bin) = gltf_parts(mesh, None);
    glb_container(&json, &bin)
}

/// The mesh as a `.gltf` JSON document whose buffer is the file `bin_uri`, and that buffer's
/// bytes (the layout of [`glb_bytes`]).
pub fn gltf_bytes(mesh: &Mesh, bin_uri: &str) -> (Vec<u8>, Vec<u8>) {
    let (json, bin) = gltf_parts(mesh, Some(bin_uri));
    (json.into_bytes(), bin)
}

fn gltf_parts(mesh: &Mesh, uri: Option<&str>) -> (String, Vec<u8>) {
    let positions = mesh.positions();
    let mut bin = Vec::with_capacity(positions.len() * 12 + mesh.triangle_count() * 12);
    for p in positions {
        for v in p.to_array() {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    let position_bytes = bin.len();
    for &i in mesh.triangles().iter().flatten() {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let (min, max) = positions
        .iter()
        .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let uri = uri.map_or_else(String::new, |u| format!(r#""uri":"{u}","#));
    let json = format!(
        r#"{{"asset":{{"version":"2.0","generator":"occult"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},
{{"bufferView":1,"componentType":5125,"count":{},"type":"SCALAR"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{position_bytes}}},{{"buffer":0,"byteOffset":{position_bytes},"byteLength":{}}}],
"buffers":[{{{uri}"byteLength":{}}}]}}"#,
        positions.len(),
        min.x,
        min.y,
        min.z,
        max.x,
        max.y,
        max.z,
        mesh.triangle_count() * 3,
        bin.len() - position_bytes,
        bin.len()
    );
    (json, bin)
}

/// A GLB container (glTF §4) of `json` and `bin`, each chunk padded to 4 bytes.
pub fn glb_container(json: &str, bin: &[u8]) -> Vec<u8> {
    let json_len = json.len().next_multiple_of(4);
    let bin_len = bin.len().next_multiple_of(4);
    let total = 12 + 8 + json_len + 8 + bin_len;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    // GLB lengths are 32-bit; larger files cannot be written.
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_len as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(json.as_bytes());
    out.resize(12 + 8 + json_len, b' ');
    out.extend_from_slice(&(bin_len as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out.resize(total, 0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::load::{load_bytes, load_bytes_with};
    use std::collections::HashMap;
    use std::path::{Path, PathBuf};

    fn tetrahedron() -> Mesh {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(0.1, 0.2, 1.5)];
        Mesh::new(positions, vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]]).expect("valid mesh")
    }

    fn same_mesh(loaded: &crate::load::LoadedScene, mesh: &Mesh) {
        let flat = loaded.scene.flatten(100).expect("flatten");
        assert_eq!(flat.triangle_count(), mesh.triangle_count());
        for t in 0..mesh.triangle_count() {
            assert_eq!(flat.triangle_positions(t), mesh.triangle_positions(t));
        }
    }

    #[test]
    fn every_format_round_trips() {
        let mesh = tetrahedron();
        let load = |name: &str, bytes: &[u8]| load_bytes(Path::new(name), bytes).expect("loads");
        same_mesh(&load("t.obj", &obj_bytes(&mesh)), &mesh);
        for encoding in [
            PlyEncoding::Ascii,
            PlyEncoding::BinaryLittleEndian,
            PlyEncoding::BinaryBigEndian,
        ] {
            same_mesh(&load("t.ply", &ply_bytes(&mesh, encoding)), &mesh);
        }
        same_mesh(&load("t.glb", &glb_bytes(&mesh)), &mesh);
        let (json, bin) = gltf_bytes(&mesh, "t.bin");
        let files = HashMap::from([(PathBuf::from("m/t.bin"), bin)]);
        same_mesh(
            &load_bytes_with(Path::new("m/t.gltf"), &json, &files).expect("loads"),
            &mesh,
        );
    }
}
