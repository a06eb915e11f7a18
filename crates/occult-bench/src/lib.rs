//! # occult-bench
//!
//! Fixed workloads shared by the criterion benchmarks (`cargo bench -p occult-bench`) and the
//! examples: the `terrain` anchor view, random triangle sets of three sizes, and recorded
//! camera paths on generated scenes. The cross-renderer invariant tests live in
//! `occult-harness` (`tests/invariants/`).
#![deny(missing_docs)]

use std::sync::Arc;

use occult_core::{Camera, Mesh, Scene, Vec3, View};
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
