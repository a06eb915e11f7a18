//! Particle culling with an N-buffer (Décoret 2005 §3.2): a scene drawn with `zbuffer`, then
//! many screen-aligned sprites among its geometry, each tested in constant time against a
//! min N-buffer of the scene's depth, or all drawn.
//!
//! Cost: one `zbuffer` frame, one N-buffer build (with culling), and the sprites' tests and
//! draws; the frame buffer (16 bytes a pixel) and the N-buffer's levels.

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Scene, View};
use occult_raster::{shade, Extremum, Frame, NBuffer, RasterConfig, Rasterizer};
use occult_render::nbuffer::particles::{draw_particles, ParticleCounts, Particles};
use occult_render::{Algorithm, RenderOptions};

use crate::ExperimentError;

/// The particles and how they are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticlesConfig {
    /// Number of particles.
    pub count: usize,
    /// Largest sprite side, pixels.
    pub max_sprite: u32,
    /// Only powers of two as sprite sides (one N-buffer lookup each).
    pub power_of_two: bool,
    /// Cull the sprites against an N-buffer of the scene's depth; otherwise draw them all.
    pub cull: bool,
    /// Test the four-lookup sprites in one batched call (same results; for measuring it).
    pub batch: bool,
    /// Share of the scene's height, from the ground, that the particles fill, in (0, 1].
    pub fill: f32,
    /// Seed of the placement.
    pub seed: u64,
}

/// What a particles run measured, and its frame.
#[derive(Debug)]
pub struct ParticlesRun {
    /// The scene and the sprites, shaded.
    pub frame: Frame,
    /// The sprites' counts.
    pub counts: ParticleCounts,
    /// Levels of the N-buffer (0 without culling).
    pub nbuffer_levels: u32,
    /// Rendering the scene with `zbuffer`, ms.
    pub scene_ms: f64,
    /// Building the N-buffer, ms (0 without culling).
    pub nbuffer_ms: f64,
    /// Culling and drawing the sprites, ms (N-buffer build excluded).
    pub draw_ms: f64,
    /// The N-buffer tests alone, ms (part of `draw_ms`).
    pub cull_ms: f64,
}

/// Scatters the particles of `config` over `scene`, renders the scene from `view` with
/// `zbuffer`, then culls and draws the sprites into the same frame and shades it. Sprite item
/// ids follow the scene's.
///
/// # Errors
/// Bad particle parameters ([`Particles::scatter`]), the scene's `zbuffer` failing, frame or
/// N-buffer allocation.
pub fn particles(scene: &Arc<Scene>, view: &View, config: &ParticlesConfig) -> Result<ParticlesRun, ExperimentError> {
    let particles = Particles::scatter(
        &scene.bounds(),
        config.count,
        config.max_sprite,
        config.power_of_two,
        config.fill,
        config.seed,
    )?;
    let mut z = Algorithm::ZBUFFER
        .build(Arc::clone(scene), &RenderOptions::default())
        .map_err(ExperimentError::BuildZbuffer)?;
    let mut frame = Frame::new(view.width(), view.height())?;
    let t = Instant::now();
    z.render(view, &mut frame)
        .map_err(|source| ExperimentError::RenderScene {
            camera_index: None,
            source,
        })?;
    let scene_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut raster = Rasterizer::new(RasterConfig::default())?;
    let t = Instant::now();
    let nb = if config.cull {
        Some(NBuffer::with_levels(
            Extremum::Min,
            frame.depth(),
            view.width(),
            view.height(),
            particles.levels_needed(),
        )?)
    } else {
        None
    };
    let nbuffer_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let counts = draw_particles(
        &mut raster,
        view,
        &mut frame,
        &particles,
        scene.item_count(),
        nb.as_ref(),
        config.batch,
    )?;
    let draw_ms = t.elapsed().as_secs_f64() * 1e3;
    let cull_ms = counts.cull_time.as_secs_f64() * 1e3;
    shade(&mut frame, scene, view);
    Ok(ParticlesRun {
        frame,
        nbuffer_levels: nb.as_ref().map_or(0, |n| n.level_count()),
        counts,
        scene_ms,
        nbuffer_ms,
        draw_ms,
        cull_ms,
    })
}
