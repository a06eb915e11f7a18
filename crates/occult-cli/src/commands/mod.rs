//! One module per subcommand: each turns its validated arguments into library calls and
//! writes what they return.

pub mod algos;
pub mod compare;
pub mod info;
pub mod mpi_model;
pub mod particles;
pub mod render;
pub mod scenes;
pub mod shadows;
pub mod suite;
pub mod sweep;
pub mod walk;

use std::time::Instant;

use anyhow::{Context, Result};
use occult_render::{AlgoSpec, Renderer};

use crate::progress::Progress;
use crate::scene::LoadedScene;

/// Builds `algo` on `scene` (sort-last over the ranks under `mpirun`) behind a spinner
/// (`preparing NAME`), prepared for frames of `width × height` ([`Renderer::prepare`]);
/// returns the renderer, its preprocessing time in ms, and the spinner, still shown.
///
/// # Errors
/// The renderer's build error, naming it.
pub fn build_renderer(
    algo: &AlgoSpec,
    scene: &LoadedScene,
    width: u32,
    height: u32,
) -> Result<(Box<dyn Renderer>, f64, Progress)> {
    let progress = Progress::spinner(format!("preparing {}", algo.label()));
    let t = Instant::now();
    let mut renderer = algo
        .build(scene.scene.clone(), &crate::ranks::render_options(false))
        .with_context(|| format!("building {}", algo.label()))?;
    renderer
        .prepare(width, height)
        .with_context(|| format!("preparing {} for {width}x{height} frames", algo.label()))?;
    Ok((renderer, t.elapsed().as_secs_f64() * 1e3, progress))
}
