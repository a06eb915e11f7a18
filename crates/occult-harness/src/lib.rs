//! # occult-harness
//!
//! occult's experiments, between the renderers (`occult-render`) and the command line
//! (`occult-cli`): each takes a built scene, cameras and a configuration, runs the renderers or
//! culling passes, times them, decides what is identical to what, and returns a report. None
//! prints, reads arguments or writes files; long runs report progress through a callback, for
//! the caller's progress bars.
//!
//! | module | experiment |
//! | --- | --- |
//! | [`compare`] | several renderers over one camera path, against a reference and the oracle |
//! | [`sweep`] | one renderer parameter varied over values, a comparison per value |
//! | [`particles`] | sprites among a scene, culled against an N-buffer or all drawn (Décoret §3.2) |
//! | [`shadows`] | spot-light shadow volumes, clamped with litmaps and N-buffers or not (Décoret §3.3) |
//! | [`suite`] | the performance yardstick: a versioned matrix of cases, every renderer, geometric means, worst cases and violations |
//! | [`memory`] | whole-process peak memory, opt-in |
//!
//! The cross-renderer invariant tests (DESIGN invariant 2: conservative renderers are
//! bit-identical to `zbuffer`) live in this crate's `tests/invariants/`, one test binary.
//!
//! ```
//! use std::sync::Arc;
//! use occult_core::{Camera, Mesh, Scene, Vec3};
//! use occult_harness::compare::{compare, CompareConfig};
//! use occult_render::Algorithm;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])?;
//! let scene = Arc::new(Scene::from_mesh("tri", mesh)?);
//! let cameras = [Camera::look_at(Vec3::new(0.3, 0.3, 2.0), Vec3::new(0.3, 0.3, 0.0))];
//! let config = CompareConfig::new([Algorithm::ZBUFFER, Algorithm::FRUSTUM], 32, 32);
//! let report = compare(scene, &cameras, &config, &mut |_| {})?;
//! let frustum = report.renderer("frustum").expect("frustum is in the report");
//! assert_eq!(frustum.frames_identical, Some(1));
//! assert_eq!(report.process_peak_rss_bytes, None); // not asked for: process state untouched
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

pub mod compare;
pub mod memory;
pub mod particles;
pub mod shadows;
pub mod suite;
pub mod sweep;

use occult_raster::RasterError;
use occult_render::RenderError;
use thiserror::Error;

/// Errors of the [`particles`] and [`shadows`] runs.
#[derive(Debug, Error)]
pub enum ExperimentError {
    /// The `zbuffer` that draws the scene could not be built.
    #[error("building zbuffer")]
    BuildZbuffer(#[source] RenderError),
    /// The scene could not be rendered from a camera (numbered along the path, when there is
    /// one).
    #[error("rendering the scene{}", camera_index.map_or(String::new(), |i| format!(", camera {i}")))]
    RenderScene {
        /// The camera's position in the path.
        camera_index: Option<usize>,
        /// Why.
        source: RenderError,
    },
    /// Bad parameters of the experiment, or a failure of its passes.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// Frames or buffers could not be allocated.
    #[error(transparent)]
    Raster(#[from] RasterError),
}
