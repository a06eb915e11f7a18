//! `occult compare`: several renderers, the same scenes and camera path, one process
//! ([`occult_render::compare`] does the measuring; this writes it out).

use anyhow::{bail, Context, Result};
use occult_render::compare::{compare, CompareConfig, CompareProgress, CompareReport};
use occult_render::RenderOptions;
use serde::Serialize;

use crate::args::CompareArgs;
use crate::output::{self, opt_field};
use crate::plot::{self, Panel, Series};
use crate::progress::Progress;
use crate::scene::{self, SceneSummary};

/// What `--json` holds: `runs` has one entry per `--scene`, in order.
#[derive(Serialize)]
struct CompareOut<'a> {
    tool: &'static str,
    version: &'static str,
    path: &'a str,
    algorithms: Vec<String>,
    runs: Vec<RunOut<'a>>,
}

/// One scene's comparison: the scene, then the harness's report inline.
#[derive(Serialize)]
struct RunOut<'a> {
    scene: SceneSummary,
    #[serde(flatten)]
    report: &'a CompareReport,
}

const CSV_HEADER: [&str; 11] = [
    "scene",
    "triangles",
    "renderer",
    "frame",
    "time_ms",
    "triangles_submitted",
    "triangles_rasterized",
    "triangles_visible",
    "identical",
    "item_error",
    "psnr_db",
];

/// Runs the command.
pub fn run(a: CompareArgs) -> Result<()> {
    output::check_outputs([&a.json, &a.csv, &a.plot, &a.plot_scaling])?;
    if a.plot_scaling.is_some() && a.scene.len() < 2 {
        bail!("--plot-scaling needs two or more --scene values (one point per scene)");
    }
    let config = CompareConfig {
        algorithms: a.algos.0.clone(),
        options: RenderOptions::default(),
        width: a.size.width,
        height: a.size.height,
    };
    let mut runs: Vec<(SceneSummary, CompareReport)> = Vec::new();
    for spec in &a.scene {
        let scene = scene::load(spec)?;
        let cameras = scene::path(&a.path, &scene)?;
        let progress = Progress::bar(cameras.len() as u64, format!("{spec}: preparing"));
        let report = compare(scene.scene.clone(), &cameras, &config, &mut |event| match event {
            CompareProgress::Building { label, .. } => progress.set_message(format!("{spec}: preparing {label}")),
            CompareProgress::Built { .. } => progress.set_message(format!("{spec}: rendering")),
            CompareProgress::Frame { .. } => progress.inc(),
        })
        .with_context(|| format!("comparing on scene '{spec}'"))?;
        drop(progress);
        let summary = scene.summary();
        say_raw!("{}", report_text(&summary, &a.path, &report));
        runs.push((summary, report));
    }

    if let Some(p) = &a.json {
        let out = CompareOut {
            tool: "occult",
            version: env!("CARGO_PKG_VERSION"),
            path: &a.path,
            algorithms: a.algos.0.iter().map(|a| a.label()).collect(),
            runs: runs
                .iter()
                .map(|(scene, report)| RunOut {
                    scene: scene.clone(),
                    report,
                })
                .collect(),
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.csv {
        output::write_csv(p, &CSV_HEADER, &csv_rows(&runs))?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.plot {
        let panels: Vec<Panel> = runs.iter().map(|(s, r)| frame_time_panel(s, &a.path, r)).collect();
        plot::draw(p, &panels)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.plot_scaling {
        plot::draw(p, &[scaling_panel(&a.path, &runs)])?;
        say!("wrote {}", p.display());
    }
    Ok(())
}

/// The text report of one scene: a header, the table, phases, and warnings.
fn report_text(scene: &SceneSummary, path: &str, r: &CompareReport) -> String {
    let mut out = format!(
        "\nscene {}: {} triangles ({} unique), {} in memory, built in {} ms\n",
        scene.label(),
        output::count(scene.triangles as f64),
        output::count(scene.unique_triangles as f64),
        output::bytes(scene.memory_bytes as u64),
        output::millis(scene.build_ms)
    );
    for w in &scene.warnings {
        out += &format!("  warning: {w}\n");
    }
    out += &format!(
        "path {path}: {} frames at {}x{}, {} threads; reference {}\n\n",
        r.frames, r.width, r.height, r.threads, r.reference_note
    );
    let header = [
        "renderer",
        "mean ms",
        "p95 ms",
        "vs zbuffer",
        "vs oracle",
        "submitted/frame",
        "rasterized/frame",
        "visible/frame",
        "identical",
        "error",
        "prepare ms",
        "memory",
    ];
    let mut rows: Vec<Vec<String>> = r
        .renderers
        .iter()
        .map(|x| {
            let mut name = x.name.to_string();
            if x.is_reference {
                name.push_str(" (ref)");
            }
            let error = if x.frames_identical == x.frames {
                "-".to_string()
            } else {
                let psnr = x.min_psnr_db.map_or(String::new(), |p| format!(", {p:.1} dB"));
                format!("{:.3}%{psnr}", 100.0 * x.mean_item_error)
            };
            vec![
                name,
                output::millis(x.mean_ms),
                output::millis(x.p95_ms),
                x.speedup_vs_zbuffer.map_or("-".into(), |s| format!("{s:.2}x")),
                x.vs_oracle.map_or("-".into(), |s| format!("{s:.2}x")),
                output::count(x.stats.triangles_submitted),
                output::count(x.triangles_rasterized),
                output::count(x.triangles_visible),
                format!("{}/{}", x.frames_identical, x.frames),
                error,
                output::millis(x.prepare_ms),
                output::bytes(x.memory_bytes as u64),
            ]
        })
        .collect();
    let o = &r.oracle;
    let visible_mean = o.triangles_visible.iter().sum::<u64>() as f64 / o.triangles_visible.len().max(1) as f64;
    rows.push(vec![
        "oracle".into(),
        output::millis(o.mean_ms),
        output::millis(o.p95_ms),
        "-".into(),
        "1.00x".into(),
        output::count(visible_mean),
        output::count(visible_mean),
        output::count(visible_mean),
        format!("{}/{}", o.frames_identical, r.frames),
        "-".into(),
        "-".into(),
        "-".into(),
    ]);
    out += &output::table(&header, &rows);
    let w = r.renderers.iter().map(|x| x.name.len()).max().unwrap_or(0);
    out += "\nmean time per phase (ms):\n";
    for x in &r.renderers {
        let phases: Vec<String> = x
            .phases
            .iter()
            .map(|p| format!("{} {}", output::phase_name(&p.phase), output::millis(p.mean_ms)))
            .collect();
        out += &format!("  {:<w$} {}\n", x.name, phases.join(", "));
    }
    if r.renderers.iter().any(|x| !x.stats.counters.is_empty()) {
        out += "\nmean counters per frame:\n";
        for x in r.renderers.iter().filter(|x| !x.stats.counters.is_empty()) {
            let counters: Vec<String> = x
                .stats
                .counters
                .iter()
                .map(|(k, v)| format!("{k} {}", output::count(*v)))
                .collect();
            out += &format!("  {:<w$} {}\n", x.name, counters.join(", "));
        }
    }
    for s in &r.skipped {
        out += &format!("skipped {}: {}\n", s.name, s.reason);
    }
    for x in &r.renderers {
        if x.conservative && x.frames_identical < x.frames {
            out += &format!(
                "WARNING: {} is conservative but {} of {} frames differ from {} (DESIGN invariant 2)\n",
                x.name,
                x.frames - x.frames_identical,
                x.frames,
                r.reference
            );
        }
    }
    if o.frames_identical < r.frames {
        out += &format!(
            "WARNING: rasterizing the visible set reproduced only {} of {} reference frames\n",
            o.frames_identical, r.frames
        );
    }
    if let Some(rss) = r.process_peak_rss_bytes {
        out += &format!(
            "process peak RSS (whole process, all renderers and the scene): {}\n",
            output::bytes(rss)
        );
    }
    out
}

fn csv_rows(runs: &[(SceneSummary, CompareReport)]) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for (scene, r) in runs {
        for x in &r.renderers {
            for (i, f) in x.per_frame.iter().enumerate() {
                rows.push(vec![
                    scene.spec.clone(),
                    scene.triangles.to_string(),
                    x.name.to_string(),
                    i.to_string(),
                    format!("{}", f.time_ms),
                    f.triangles_submitted.to_string(),
                    f.triangles_rasterized.to_string(),
                    r.oracle.triangles_visible[i].to_string(),
                    f.identical.to_string(),
                    opt_field(f.item_error),
                    opt_field(f.psnr_db),
                ]);
            }
        }
        for (i, (&t, &v)) in r
            .oracle
            .per_frame_ms
            .iter()
            .zip(&r.oracle.triangles_visible)
            .enumerate()
        {
            rows.push(vec![
                scene.spec.clone(),
                scene.triangles.to_string(),
                "oracle".into(),
                i.to_string(),
                format!("{t}"),
                v.to_string(),
                String::new(),
                v.to_string(),
                String::new(),
                String::new(),
                String::new(),
            ]);
        }
    }
    rows
}

fn frame_time_panel(scene: &SceneSummary, path: &str, r: &CompareReport) -> Panel {
    let mut series: Vec<Series> = r
        .renderers
        .iter()
        .map(|x| Series {
            name: format!("{} (mean {} ms)", x.name, output::millis(x.mean_ms)),
            points: x
                .per_frame
                .iter()
                .enumerate()
                .map(|(i, f)| (i as f64, f.time_ms))
                .collect(),
            dashed: false,
        })
        .collect();
    series.push(Series {
        name: format!(
            "oracle: visible triangles only (mean {} ms)",
            output::millis(r.oracle.mean_ms)
        ),
        points: r
            .oracle
            .per_frame_ms
            .iter()
            .enumerate()
            .map(|(i, &t)| (i as f64, t))
            .collect(),
        dashed: true,
    });
    Panel {
        title: format!(
            "{} ({} triangles), path {path}, {}x{}",
            scene.spec,
            output::count(scene.triangles as f64),
            r.width,
            r.height
        ),
        x_label: "frame".into(),
        y_label: "frame time (ms, log)".into(),
        log_x: false,
        series,
    }
}

fn scaling_panel(path: &str, runs: &[(SceneSummary, CompareReport)]) -> Panel {
    let mut names: Vec<&str> = Vec::new();
    for (_, r) in runs {
        for x in &r.renderers {
            if !names.contains(&x.name.as_str()) {
                names.push(&x.name);
            }
        }
    }
    let mut series: Vec<Series> = names
        .iter()
        .map(|&name| Series {
            name: name.to_string(),
            points: runs
                .iter()
                .filter_map(|(s, r)| r.renderer(name).map(|x| (s.triangles as f64, x.mean_ms)))
                .collect(),
            dashed: false,
        })
        .collect();
    series.push(Series {
        name: "oracle: visible triangles only".into(),
        points: runs
            .iter()
            .map(|(s, r)| (s.triangles as f64, r.oracle.mean_ms))
            .collect(),
        dashed: true,
    });
    let (w, h) = runs.first().map_or((0, 0), |(_, r)| (r.width, r.height));
    Panel {
        title: format!("mean frame time against scene size, path {path}, {w}x{h}"),
        x_label: "scene size (triangle instances, log)".into(),
        y_label: "mean frame time (ms, log)".into(),
        log_x: true,
        series,
    }
}
