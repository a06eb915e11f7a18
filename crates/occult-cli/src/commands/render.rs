//! `occult render`: one frame.

use std::time::Instant;

use anyhow::{Context, Result};
use occult_core::{Camera, View};
use occult_raster::{shade, Frame};
use serde::Serialize;

use crate::args::RenderArgs;
use occult_render::FrameStatsMs;

use crate::output;
use crate::scene::{self, SceneSummary};

/// What `--json` holds.
#[derive(Serialize)]
struct RenderOut<'a> {
    scene: SceneSummary,
    algorithm: &'a str,
    width: u32,
    height: u32,
    camera: Camera,
    /// Preprocessing (renderer build) time, ms.
    prepare_ms: f64,
    /// Wall time of the render call, ms.
    time_ms: f64,
    /// Exactly visible triangles (distinct items in the item buffer).
    triangles_visible: u64,
    /// Pixels holding a triangle.
    covered_pixels: u64,
    /// Renderer's own structures, bytes.
    renderer_memory_bytes: usize,
    stats: FrameStatsMs,
}

/// Runs the command.
pub fn run(a: RenderArgs) -> Result<()> {
    output::check_outputs([&Some(a.out.clone()), &a.depth_out, &a.json])?;
    a.camera.overrides.check()?;
    let scene = scene::load(&a.scene)?;
    let camera = scene::camera(&a.camera.view, &a.camera.overrides, &scene)?;
    let view = View::new(camera, a.size.width, a.size.height).context("view")?;

    let (mut renderer, prepare_ms, progress) = super::build_renderer(&a.algo, &scene, a.size.width, a.size.height)?;
    progress.set_message(format!("rendering with {}", a.algo.label()));
    let mut frame = Frame::new(a.size.width, a.size.height)?;
    let t = Instant::now();
    let stats = renderer
        .render(&view, &mut frame)
        .with_context(|| format!("{} failed", a.algo.label()))?;
    let time_ms = t.elapsed().as_secs_f64() * 1e3;
    let triangles_visible = frame.visible_items().len() as u64;
    let covered_pixels = frame.covered_pixel_count();
    shade(&mut frame, &scene.scene, &view);
    output::write_color_png(&frame, &a.out)?;
    if let Some(p) = &a.depth_out {
        output::write_depth_png(&frame, p)?;
    }
    drop(progress);

    let summary = scene.summary();
    let stats = FrameStatsMs(stats.clone());
    say!(
        "scene {}: {} triangles, built in {} ms",
        summary.label(),
        output::count(summary.triangles as f64),
        output::millis(summary.build_ms)
    );
    for w in &summary.warnings {
        say!("  warning: {w}");
    }
    say!(
        "{} at {}x{}: {} ms (prepared in {} ms, {} of its own structures)",
        a.algo.label(),
        a.size.width,
        a.size.height,
        output::millis(time_ms),
        output::millis(prepare_ms),
        output::bytes(renderer.memory_bytes() as u64)
    );
    say_raw!("{}", output::stats_text(&stats.0));
    say!(
        "  {:<22} {}",
        "triangles visible",
        output::count(triangles_visible as f64)
    );
    say!("  {:<22} {}", "pixels covered", output::count(covered_pixels as f64));
    say!("wrote {}", a.out.display());
    if let Some(p) = &a.depth_out {
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.json {
        let out = RenderOut {
            scene: summary,
            algorithm: &a.algo.label(),
            width: a.size.width,
            height: a.size.height,
            camera,
            prepare_ms,
            time_ms,
            triangles_visible,
            covered_pixels,
            renderer_memory_bytes: renderer.memory_bytes(),
            stats,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    Ok(())
}
