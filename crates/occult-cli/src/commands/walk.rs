//! `occult walk`: one renderer along a camera path.

use std::time::Instant;

use anyhow::{Context, Result};
use occult_core::View;
use occult_harness::compare::TimeSummary;
use occult_raster::{shade, Frame};
use serde::Serialize;

use crate::args::WalkArgs;
use occult_render::FrameStatsMs;

use crate::output;
use crate::progress::Progress;
use crate::scene::{self, SceneSummary};

/// One frame of `--json` and `--csv`.
#[derive(Serialize)]
struct WalkFrame {
    frame: usize,
    /// Wall time of the render call, ms.
    time_ms: f64,
    /// Exactly visible triangles (item buffer).
    triangles_visible: u64,
    /// Pixels holding a triangle.
    covered_pixels: u64,
    #[serde(flatten)]
    stats: FrameStatsMs,
}

/// What `--json` holds.
#[derive(Serialize)]
struct WalkOut<'a> {
    scene: SceneSummary,
    path: String,
    algorithm: &'a str,
    width: u32,
    height: u32,
    prepare_ms: f64,
    renderer_memory_bytes: usize,
    time: TimeSummary,
    frames: Vec<WalkFrame>,
}

const CSV_HEADER: [&str; 15] = [
    "frame",
    "time_ms",
    "triangles_submitted",
    "triangles_rasterized",
    "triangles_visible",
    "covered_pixels",
    "fragments_written",
    "nodes_visited",
    "boxes_tested",
    "boxes_culled",
    "rects_tested",
    "rects_culled",
    "rays_cast",
    "samples_drawn",
    "renderer_total_ms",
];

/// Runs the command.
pub fn run(a: WalkArgs) -> Result<()> {
    output::check_outputs([&a.json, &a.csv, &a.path_out])?;
    if let Some(dir) = &a.frames_out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create directory '{}'", dir.display()))?;
    }
    let scene = scene::load(&a.scene)?;
    let cameras = scene::path(&a.frames.path, &scene)?;
    let views = cameras
        .iter()
        .enumerate()
        .map(|(i, c)| {
            View::new(*c, a.frames.size.width, a.frames.size.height)
                .with_context(|| format!("camera {i} of path '{}'", a.frames.path))
        })
        .collect::<Result<Vec<_>>>()?;
    if let Some(p) = &a.path_out {
        occult_scenes::path::write_path_json(p, &cameras)?;
    }

    let (mut renderer, prepare_ms, progress) =
        super::build_renderer(&a.algo, &scene, a.frames.size.width, a.frames.size.height)?;
    drop(progress);

    let progress = Progress::bar(views.len() as u64, format!("{} on {}", a.algo.label(), a.frames.path));
    let mut frame = Frame::new(a.frames.size.width, a.frames.size.height)?;
    let mut frames = Vec::with_capacity(views.len());
    for (i, view) in views.iter().enumerate() {
        let t = Instant::now();
        let stats = renderer
            .render(view, &mut frame)
            .with_context(|| format!("{} failed on frame {i}", a.algo.label()))?;
        let time_ms = t.elapsed().as_secs_f64() * 1e3;
        frames.push(WalkFrame {
            frame: i,
            time_ms,
            triangles_visible: frame.visible_items().len() as u64,
            covered_pixels: frame.covered_pixel_count(),
            stats: FrameStatsMs(stats.clone()),
        });
        if let Some(dir) = &a.frames_out {
            shade(&mut frame, &scene.scene, view);
            output::write_color_png(&frame, &dir.join(format!("frame_{i:05}.png")))?;
        }
        progress.inc();
    }
    drop(progress);

    let times: Vec<f64> = frames.iter().map(|f| f.time_ms).collect();
    let time = TimeSummary::of(&times);
    let n = frames.len() as f64;
    let mean = |f: fn(&WalkFrame) -> u64| frames.iter().map(|x| f(x) as f64).sum::<f64>() / n;
    let summary = scene.summary();
    say!("{}", summary.walk_line(&a.frames, frames.len()));
    say!(
        "{}: mean {} ms, p95 {} ms, min {} ms, max {} ms; prepared in {} ms, {} of its own structures",
        a.algo.label(),
        output::millis(time.mean_ms),
        output::millis(time.p95_ms),
        output::millis(time.min_ms),
        output::millis(time.max_ms),
        output::millis(prepare_ms),
        output::bytes(renderer.memory_bytes() as u64)
    );
    say!(
        "  per frame: {} triangles submitted, {} rasterized, {} visible",
        output::count(mean(|f| f.stats.0.triangles_submitted)),
        output::count(mean(|f| f.stats.0.triangles_rasterized)),
        output::count(mean(|f| f.triangles_visible))
    );
    if let Some(dir) = &a.frames_out {
        say!("wrote {} frames to {}", frames.len(), dir.display());
    }
    if let Some(p) = &a.path_out {
        say!("wrote the path's {} cameras to {}", cameras.len(), p.display());
    }
    if let Some(p) = &a.csv {
        // The renderer's own counters follow the fixed columns, in the order first reported.
        let mut own_counters: Vec<&'static str> = Vec::new();
        for f in &frames {
            for &(k, _) in &f.stats.0.counters.0 {
                if !own_counters.contains(&k) {
                    own_counters.push(k);
                }
            }
        }
        let rows: Vec<Vec<String>> = frames
            .iter()
            .map(|f| {
                let s = &f.stats.0;
                let mut row = vec![f.frame.to_string(), format!("{}", f.time_ms)];
                row.extend(
                    [
                        s.triangles_submitted,
                        s.triangles_rasterized,
                        f.triangles_visible,
                        f.covered_pixels,
                    ]
                    .iter()
                    .map(u64::to_string),
                );
                row.extend(s.fixed_counters()[2..].iter().map(|(_, v)| v.to_string()));
                row.push(format!("{}", s.total.as_secs_f64() * 1e3));
                row.extend(own_counters.iter().map(|k| s.counters.get(k).to_string()));
                row
            })
            .collect();
        let header: Vec<&str> = CSV_HEADER.iter().chain(&own_counters).copied().collect();
        output::write_csv(p, &header, &rows)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.json {
        let out = WalkOut {
            scene: summary,
            path: a.frames.path.text.clone(),
            algorithm: &a.algo.label(),
            width: a.frames.size.width,
            height: a.frames.size.height,
            prepare_ms,
            renderer_memory_bytes: renderer.memory_bytes(),
            time,
            frames,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    Ok(())
}
