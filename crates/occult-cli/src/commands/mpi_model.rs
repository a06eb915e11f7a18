//! `occult mpi-model`: sort-last compositing's communication per frame and rank, measured over
//! 2–8 thread ranks (the bytes do not depend on the transport) and binary swap's model for
//! 64–1024 ranks at a large frame size (`occult_mpi::model`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use occult_core::View;
use occult_mpi::model::{self, Link, RanksCost};
use serde::Serialize;

use crate::args::{parse_scene, parse_size, FramesArgs, SceneArg, Size};
use crate::output;
use crate::plot::{self, Panel, Series};
use crate::scene;

/// `occult mpi-model`.
#[derive(Debug, Args)]
pub struct MpiModelArgs {
    /// Scene of the measurements (spec or file).
    #[arg(long, value_name = "SPEC", default_value = "city:blocks=8", value_parser = parse_scene)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub frames: FramesArgs,
    /// Largest rank count measured (from 2).
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub max_ranks: usize,
    /// Frame size of the model.
    #[arg(long, value_name = "WxH", default_value = "3840x2160", value_parser = parse_size)]
    pub model_size: Size,
    /// Rank counts of the model, comma-separated.
    #[arg(
        long,
        value_name = "LIST",
        default_value = "64,128,256,512,1024",
        value_delimiter = ','
    )]
    pub model_ranks: Vec<usize>,
    /// The interconnect's latency α, µs (default: InfiniBand EDR).
    #[arg(long, value_name = "US", default_value_t = Link::default().latency_us)]
    pub latency_us: f64,
    /// The interconnect's bandwidth β per rank, GB/s (default: InfiniBand EDR).
    #[arg(long, value_name = "GB_S", default_value_t = Link::default().bandwidth_gb_s)]
    pub bandwidth_gb_s: f64,
    /// Everything out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// One row per rank count (CSV).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Bytes per rank and frame, and compositing time, against ranks (PNG).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
}

/// What `--json` holds.
#[derive(Serialize)]
struct ModelOut {
    scene: String,
    link: Link,
    merge_ns_per_pixel: f64,
    measured: Vec<RanksCost>,
    /// The model at the measured sizes and ranks (to set beside the measurements).
    model_at_measured: Vec<RanksCost>,
    model: Vec<RanksCost>,
}

/// Runs the command.
pub fn run(a: MpiModelArgs) -> Result<()> {
    output::check_outputs([&a.json, &a.csv, &a.plot])?;
    if a.max_ranks < 2 || a.max_ranks > 64 {
        anyhow::bail!("--max-ranks {}: measure 2 to 64 thread ranks", a.max_ranks);
    }
    if !(a.latency_us >= 0.0 && a.bandwidth_gb_s > 0.0) {
        anyhow::bail!("--latency-us must be ≥ 0 and --bandwidth-gb-s > 0");
    }
    let scene = scene::load(&a.scene)?;
    let cameras = scene::path(&a.frames.path, &scene)?;
    let (w, h) = (a.frames.size.width, a.frames.size.height);
    let views = cameras
        .iter()
        .enumerate()
        .map(|(i, c)| View::new(*c, w, h).with_context(|| format!("camera {i} of path '{}'", a.frames.path)))
        .collect::<Result<Vec<_>>>()?;
    let link = Link {
        latency_us: a.latency_us,
        bandwidth_gb_s: a.bandwidth_gb_s,
    };
    let gamma = model::merge_ns_per_pixel(w, h);
    let mut measured = Vec::new();
    let mut model_at_measured = Vec::new();
    for ranks in 2..=a.max_ranks {
        measured.push(model::measure(&scene.scene, &views, ranks).with_context(|| format!("{ranks} thread ranks"))?);
        model_at_measured.push(model::model(ranks, w, h, link, gamma));
    }
    let (mw, mh) = (a.model_size.width, a.model_size.height);
    let modelled: Vec<RanksCost> = a
        .model_ranks
        .iter()
        .map(|&p| model::model(p, mw, mh, link, gamma))
        .collect();

    say!(
        "{} at {w}x{h}, {} frames; merge {:.2} ns/pixel here; link {} µs, {} GB/s",
        scene.spec,
        views.len(),
        gamma,
        a.latency_us,
        a.bandwidth_gb_s
    );
    say!(
        "{:>6} {:>10} {:>16} {:>16} {:>16} {:>14}",
        "ranks",
        "size",
        "sent/rank max",
        "model",
        "sent/rank mean",
        "composite ms"
    );
    for (m, p) in measured.iter().zip(&model_at_measured) {
        say!(
            "{:>6} {:>10} {:>16} {:>16} {:>16} {:>14.3}",
            m.ranks,
            format!("{w}x{h}"),
            output::bytes(m.bytes_sent_max as u64),
            output::bytes(p.bytes_sent_max as u64),
            output::bytes(m.bytes_sent_mean as u64),
            m.composite_ms
        );
    }
    say!("model (binary swap, α–β):");
    for p in &modelled {
        say!(
            "{:>6} {:>10} {:>16} {:>16} {:>16} {:>14.3}",
            p.ranks,
            format!("{mw}x{mh}"),
            output::bytes(p.bytes_sent_max as u64),
            "",
            output::bytes(p.bytes_sent_mean as u64),
            p.composite_ms
        );
    }
    if let Some(p) = &a.csv {
        let rows: Vec<Vec<String>> = measured
            .iter()
            .chain(&model_at_measured)
            .chain(&modelled)
            .map(|c| {
                vec![
                    if c.measured { "measured" } else { "model" }.to_string(),
                    c.ranks.to_string(),
                    c.width.to_string(),
                    c.height.to_string(),
                    format!("{}", c.bytes_sent_max),
                    format!("{}", c.bytes_sent_mean),
                    format!("{}", c.bytes_received_root),
                    format!("{}", c.composite_ms),
                ]
            })
            .collect();
        let header = [
            "kind",
            "ranks",
            "width",
            "height",
            "bytes_sent_max",
            "bytes_sent_mean",
            "bytes_received_root",
            "composite_ms",
        ];
        output::write_csv(p, &header, &rows)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.plot {
        let series = |name: &str, costs: &[RanksCost], y: fn(&RanksCost) -> f64, dashed: bool| Series {
            name: name.to_string(),
            points: costs.iter().map(|c| (c.ranks as f64, y(c))).collect(),
            dashed,
        };
        let mb = |c: &RanksCost| c.bytes_sent_max / 1e6;
        let model_line: Vec<RanksCost> = [2usize, 4, 8, 16, 32, 64, 128, 256, 512, 1024]
            .iter()
            .map(|&r| model::model(r, mw, mh, link, gamma))
            .collect();
        let panels = [
            Panel {
                title: format!("sort-last compositing: MB sent per rank and frame (binary swap; measured at {w}x{h})"),
                x_label: "ranks".into(),
                y_label: "MB per rank and frame".into(),
                log_x: true,
                integer_x: true,
                series: vec![
                    series(&format!("measured, {w}x{h}"), &measured, mb, false),
                    series(&format!("model, {w}x{h}"), &model_at_measured, mb, true),
                    series(&format!("model, {mw}x{mh}"), &model_line, mb, false),
                ],
            },
            Panel {
                title: format!(
                    "compositing time per frame, ms (model: α {} µs, β {} GB/s, γ {:.2} ns/pixel)",
                    a.latency_us, a.bandwidth_gb_s, gamma
                ),
                x_label: "ranks".into(),
                y_label: "ms per frame".into(),
                log_x: true,
                integer_x: true,
                series: vec![
                    series(
                        &format!("measured here (thread ranks), {w}x{h}"),
                        &measured,
                        |c| c.composite_ms,
                        false,
                    ),
                    series(&format!("model, {mw}x{mh}"), &model_line, |c| c.composite_ms, false),
                ],
            },
        ];
        plot::draw(p, &panels)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.json {
        let out = ModelOut {
            scene: scene.spec.clone(),
            link,
            merge_ns_per_pixel: gamma,
            measured,
            model_at_measured,
            model: modelled,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    Ok(())
}
