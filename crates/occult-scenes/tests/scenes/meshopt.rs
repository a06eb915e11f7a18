//! glTF `EXT_meshopt_compression`: files written here, compressed with meshoptimizer's own
//! encoders (the `meshopt` crate), as gltfpack lays them out: compressed bytes in one buffer, a
//! fallback buffer without data that the views nominally point into, quantized positions.

use std::path::Path;

use occult_core::Vec3;
use occult_scenes::load::{load_file, LoadError, LoadedScene};
use occult_scenes::save::glb_container as glb;

/// A grid of `n` × `n` quads on integer corners `0..=n` in x and y, z = x + y.
fn grid(n: u32) -> (Vec<[u32; 3]>, Vec<u32>) {
    let corners: Vec<[u32; 3]> = (0..=n).flat_map(|y| (0..=n).map(move |x| [x, y, x + y])).collect();
    let at = |x: u32, y: u32| y * (n + 1) + x;
    let mut indices = Vec::new();
    for y in 0..n {
        for x in 0..n {
            indices.extend([
                at(x, y),
                at(x + 1, y),
                at(x + 1, y + 1),
                at(x, y),
                at(x + 1, y + 1),
                at(x, y + 1),
            ]);
        }
    }
    (corners, indices)
}

/// How one test file stores its grid.
struct Layout<'a> {
    /// `"uri": "..."` of the compressed buffer, or empty for a GLB's BIN chunk.
    uri: &'a str,
    /// Positions: `UNSIGNED_SHORT` padded to 8 bytes (`false`), or `FLOAT` through the
    /// `EXPONENTIAL` filter (`true`).
    float_positions: bool,
    /// Indices: `TRIANGLES` mode (`true`) or `INDICES` (`false`), both 16-bit.
    triangles_mode: bool,
}

/// The grid compressed as `layout` says: the JSON and the compressed buffer's bytes.
fn compressed_grid(n: u32, layout: &Layout<'_>) -> (String, Vec<u8>) {
    let (corners, indices) = grid(n);
    let count = corners.len();
    let (position_bytes, stride, component_type, filter) = if layout.float_positions {
        let floats: Vec<[f32; 3]> = corners.iter().map(|c| c.map(|v| v as f32)).collect();
        let encoded = meshopt::encode_filter_exp(&floats, 15, meshopt::EncodeExpMode::SharedVector);
        (
            meshopt::encode_vertex_buffer(&encoded).expect("encode positions"),
            12,
            5126,
            r#", "filter": "EXPONENTIAL""#,
        )
    } else {
        let shorts: Vec<[u16; 4]> = corners
            .iter()
            .map(|c| [c[0] as u16, c[1] as u16, c[2] as u16, 0])
            .collect();
        (
            meshopt::encode_vertex_buffer(&shorts).expect("encode positions"),
            8,
            5123,
            "",
        )
    };
    let (index_bytes, mode) = if layout.triangles_mode {
        (
            meshopt::encode_index_buffer(&indices, count).expect("encode triangles"),
            "TRIANGLES",
        )
    } else {
        (
            meshopt::encode_index_sequence(&indices, count).expect("encode indices"),
            "INDICES",
        )
    };
    let mut bin = position_bytes.clone();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let index_offset = bin.len();
    bin.extend(&index_bytes);
    let (positions_len, indices_len) = (count * stride, indices.len() * 2);
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0", "generator": "occult tests"}},
  "extensionsUsed": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
  "extensionsRequired": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0, "scale": [0.5, 0.5, 0.5]}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
  "buffers": [
    {{{uri} "byteLength": {bin_len}}},
    {{"byteLength": {fallback_len}, "extensions": {{"EXT_meshopt_compression": {{"fallback": true}}}}}}
  ],
  "bufferViews": [
    {{"buffer": 1, "byteOffset": 0, "byteLength": {positions_len}, "byteStride": {stride},
      "extensions": {{"EXT_meshopt_compression": {{"buffer": 0, "byteOffset": 0, "byteLength": {pos_compressed},
        "byteStride": {stride}, "count": {count}, "mode": "ATTRIBUTES"{filter}}}}}}},
    {{"buffer": 1, "byteOffset": {positions_len}, "byteLength": {indices_len},
      "extensions": {{"EXT_meshopt_compression": {{"buffer": 0, "byteOffset": {index_offset},
        "byteLength": {index_compressed}, "byteStride": 2, "count": {index_count}, "mode": "{mode}"}}}}}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": {component_type}, "count": {count}, "type": "VEC3",
      "min": [0, 0, 0], "max": [{n}, {n}, {two_n}]}},
    {{"bufferView": 1, "componentType": 5123, "count": {index_count}, "type": "SCALAR"}}
  ]
}}"#,
        uri = layout.uri,
        bin_len = bin.len(),
        fallback_len = positions_len + indices_len,
        pos_compressed = position_bytes.len(),
        index_compressed = index_bytes.len(),
        index_count = indices.len(),
        two_n = 2 * n,
    );
    (json, bin)
}

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("occult-loaders").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch folder");
    dir
}

/// The grid of `n` quads, scaled by the node's 0.5: its triangle count and bounds.
fn check_grid(loaded: &LoadedScene, n: u32) {
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_eq!(loaded.scene.item_count(), u64::from(2 * n * n));
    let bounds = loaded.scene.bounds();
    let half = n as f32 * 0.5;
    assert_eq!(bounds.min, Vec3::ZERO, "{bounds:?}");
    assert_eq!(bounds.max, Vec3::new(half, half, 2.0 * half), "{bounds:?}");
}

#[test]
fn meshopt_glb_with_quantized_positions_and_triangle_codec() {
    let dir = scratch("meshopt_glb_with_quantized_positions_and_triangle_codec");
    let layout = Layout {
        uri: "",
        float_positions: false,
        triangles_mode: true,
    };
    let (json, bin) = compressed_grid(40, &layout);
    let path = dir.join("grid.glb");
    std::fs::write(&path, glb(&json, &bin)).expect("write");
    check_grid(&load_file(&path).expect("loads"), 40);
}

#[test]
fn meshopt_gltf_with_exponential_float_positions_and_index_sequence() {
    let dir = scratch("meshopt_gltf_with_exponential_float_positions_and_index_sequence");
    let layout = Layout {
        uri: r#""uri": "grid.bin","#,
        float_positions: true,
        triangles_mode: false,
    };
    let (json, bin) = compressed_grid(25, &layout);
    std::fs::write(dir.join("grid.bin"), &bin).expect("write");
    let path = dir.join("grid.gltf");
    std::fs::write(&path, json).expect("write");
    check_grid(&load_file(&path).expect("loads"), 25);
}

#[test]
fn meshopt_bad_data_is_an_error_naming_file_and_view() {
    let dir = scratch("meshopt_bad_data_is_an_error_naming_file_and_view");
    let layout = Layout {
        uri: "",
        float_positions: false,
        triangles_mode: true,
    };
    let (json, bin) = compressed_grid(10, &layout);
    let load = |name: &str, json: &str, bin: &[u8]| -> LoadError {
        let path = dir.join(name);
        std::fs::write(&path, glb(json, bin)).expect("write");
        let e = load_file(&path).expect_err("must fail");
        assert!(e.to_string().contains(name), "{e}");
        e
    };
    // Garbage in place of the compressed bytes.
    let e = load("garbage.glb", &json, &vec![0xa5; bin.len()]);
    assert!(
        matches!(e, LoadError::Parse { .. }) && e.to_string().contains("buffer view 0"),
        "{e}"
    );
    // The compressed range past the end of its buffer.
    let e = load("short.glb", &json, &bin[..bin.len() / 2]);
    assert!(
        matches!(e, LoadError::Buffer { .. } | LoadError::CountMismatch { .. }),
        "{e}"
    );
    // A count no compressed data can hold: refused before anything is allocated.
    let absurd = json.replacen(r#""count": 121"#, r#""count": 4000000000"#, 1);
    assert_ne!(absurd, json);
    let e = load("absurd.glb", &absurd, &bin);
    assert!(e.to_string().contains("cannot come from"), "{e}");
    // A stride the codec forbids (it would assert): an error.
    let stride = json.replacen(r#""byteStride": 8, "count""#, r#""byteStride": 6, "count""#, 1);
    assert_ne!(stride, json);
    let e = load("stride.glb", &stride, &bin);
    assert!(e.to_string().contains("byteStride 6"), "{e}");
}
