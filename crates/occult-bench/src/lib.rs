//! # occult-bench
//!
//! Fixed workloads shared by the criterion benchmarks (`cargo bench -p occult-bench`) and the
//! examples: the `terrain` anchor view, random triangle sets of three sizes, and recorded
//! camera paths on generated scenes. The cross-renderer invariant tests live in
//! `occult-harness` (`tests/invariants/`).
#![deny(missing_docs)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use occult_core::{Camera, Mesh, Scene, Vec3, View};
use occult_scenes::save::{glb_bytes, obj_bytes, ply_bytes, PlyEncoding};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// A built scene and its default camera.
pub struct Workload {
    /// The scene.
    pub scene: Scene,
    /// Its default camera.
    pub camera: Camera,
}

/// Builds a scene from a spec (`terrain`, `city:blocks=8`, a file path).
///
/// # Panics
/// If the spec does not build: benchmarks use fixed, known-good specs.
pub fn workload(spec: &str) -> Workload {
    let built = occult_scenes::spec::parse_spec(spec)
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("benchmark scene {spec}: {e}"));
    Workload {
        scene: built.scene,
        camera: built.default_camera,
    }
}

/// The scene of `spec` and the views of the camera path `path` through it (from its default
/// camera) at `width × height`.
///
/// # Panics
/// If the spec, the path or a view is invalid: benchmarks use fixed, known-good ones.
pub fn path_views(spec: &str, path: &str, width: u32, height: u32) -> (Arc<Scene>, Vec<View>) {
    let w = workload(spec);
    let cameras = occult_scenes::path::parse_path(path, &w.scene, &w.camera)
        .unwrap_or_else(|e| panic!("benchmark path {path} on {spec}: {e}"));
    let views = cameras
        .iter()
        .map(|c| View::new(*c, width, height).expect("valid view"))
        .collect();
    (Arc::new(w.scene), views)
}

/// The anchor view: `terrain` from its default camera at 1920 × 1080.
///
/// # Panics
/// Never for the built-in generator.
pub fn terrain_view() -> (Scene, View) {
    let w = workload("terrain");
    let view = View::new(w.camera, 1920, 1080).expect("default terrain view is valid");
    (w.scene, view)
}

/// `count` random triangles whose projected size is about `size_px` pixels across, spread over
/// a 1920 × 1080 view at distance 10 (returned with the view).
///
/// # Panics
/// Never: the generated data is finite and in range.
pub fn random_triangles(count: usize, size_px: f32, seed: u64) -> (Mesh, View) {
    let cam = Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
    let view = View::new(cam, 1920, 1080).expect("valid view");
    // At distance 10 with a 60° fov, one pixel is 2·10·tan(30°)/1080 world units.
    let px = 2.0 * 10.0 * (30f32).to_radians().tan() / 1080.0;
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut p = Vec::with_capacity(count * 3);
    for _ in 0..count {
        let c = Vec3::new(
            rng.random_range(-960.0..960.0) * px,
            rng.random_range(-540.0..540.0) * px,
            rng.random_range(-1.0..1.0),
        );
        for _ in 0..3 {
            p.push(c + Vec3::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), 0.0) * (size_px * px * 1.5));
        }
    }
    let t = (0..count as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    (Mesh::new(p, t).expect("finite positions, valid indices"), view)
}

/// Quads per side of the generated height field.
pub const GRID: u32 = 512;

/// A height field of `GRID` × `GRID` quads with irregular heights (so that the text formats
/// carry full-length decimals, as scans do).
pub fn height_field() -> Mesh {
    let side = GRID + 1;
    let positions: Vec<Vec3> = (0..side * side)
        .map(|i| {
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            let h = (x * 0.173).sin() * (y * 0.131).cos() * 7.31 + (i.wrapping_mul(2_654_435_761) % 1000) as f32 * 1e-4;
            Vec3::new(x * 0.25, y * 0.25, h)
        })
        .collect();
    let mut triangles = Vec::with_capacity((2 * GRID * GRID) as usize);
    for y in 0..GRID {
        for x in 0..GRID {
            let i = y * side + x;
            triangles.push([i, i + 1, i + side + 1]);
            triangles.push([i, i + side + 1, i + side]);
        }
    }
    Mesh::new(positions, triangles).expect("valid height field")
}

/// A file of the load benchmarks: its name, the path it is loaded as, and its bytes.
pub type LoadFile = (String, PathBuf, Vec<u8>);

/// The [`height_field`] written in every format the loaders read (OBJ, PLY ascii, binary
/// little- and big-endian, GLB), in memory.
pub fn load_grid_files() -> Vec<LoadFile> {
    let mesh = height_field();
    vec![
        ("obj".to_string(), PathBuf::from("grid.obj"), obj_bytes(&mesh)),
        (
            "ply_ascii".to_string(),
            PathBuf::from("grid.ply"),
            ply_bytes(&mesh, PlyEncoding::Ascii),
        ),
        (
            "ply_binary_le".to_string(),
            PathBuf::from("grid.ply"),
            ply_bytes(&mesh, PlyEncoding::BinaryLittleEndian),
        ),
        (
            "ply_binary_be".to_string(),
            PathBuf::from("grid.ply"),
            ply_bytes(&mesh, PlyEncoding::BinaryBigEndian),
        ),
        ("glb".to_string(), PathBuf::from("grid.glb"), glb_bytes(&mesh)),
    ]
}

/// The model files (those a loader reads) directly under each folder of `root`, sorted.
///
/// # Panics
/// If a listed file cannot be read.
pub fn model_files(root: &Path) -> Vec<LoadFile> {
    let mut files = Vec::new();
    let mut folders: Vec<PathBuf> = std::fs::read_dir(root)
        .map(|entries| entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()).collect())
        .unwrap_or_default();
    folders.sort();
    for folder in folders {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        for path in paths {
            if occult_scenes::load::Format::from_path(&path).is_some() {
                let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()));
                let name = path
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                files.push((name, path, bytes));
            }
        }
    }
    files
}
