//! `occult compare`: several renderers, the same scenes and camera path, one process
//! ([`occult_harness::compare`] does the measuring; this writes it out).

use anyhow::{bail, Context, Result};
use occult_harness::compare::{
    compare, CompareConfig, CompareProgress, CompareReport, FrameRecord, Reference, RendererReport,
};
use occult_harness::memory::PeakRss;
use occult_harness::sweep::counter_names;
use occult_render::AlgoSpec;
use serde::Serialize;
use std::path::{Path, PathBuf};

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

const CSV_HEADER: [&str; 15] = [
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
    "paper_error",
    "psnr_db",
    "covered_pixels",
    "image_complexity",
    "peak_rss_bytes",
];

/// Runs the command.
pub fn run(a: CompareArgs) -> Result<()> {
    let axes: Vec<ScalingAxis> = a.plot_scaling_x.iter().map(|x| ScalingAxis::parse(x)).collect();
    let scaling_plots: Vec<(ScalingAxis, Option<PathBuf>)> = match &a.plot_scaling {
        Some(p) if axes.len() > 1 => axes.iter().map(|&x| (x, Some(x.file_for(p)))).collect(),
        p => vec![(axes[0], p.clone())],
    };
    output::check_outputs(
        [&a.json, &a.csv, &a.plot]
            .into_iter()
            .chain(scaling_plots.iter().map(|(_, p)| p)),
    )?;
    if a.plot_scaling.is_some() && a.scene.len() < 2 {
        bail!("--plot-scaling needs two or more --scene values (one point per scene)");
    }
    if a.plot.is_some() {
        check_plot_y(&a)?;
    }
    let config = CompareConfig {
        algorithms: a.algos.0.clone(),
        // Under `mpirun`: sort-last, with every rank ending a frame with the composite, as
        // the comparison reads the frames (and renders more where they differ) on every rank.
        options: crate::ranks::render_options(true),
        width: a.frames.size.width,
        height: a.frames.size.height,
        reference: a.reference.0.clone(),
        image_complexity: a.complexity || (a.plot_scaling.is_some() && axes.iter().any(|x| x.needs_image_complexity())),
        // One handle for every scene, so that the process peak survives the resets.
        peak_rss: a.peak_rss.then(PeakRss::new),
        diff_images: a.diff_out.is_some(),
    };
    if let Some(dir) = &a.diff_out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create directory '{}'", dir.display()))?;
    }
    let several = a.scene.len() > 1;
    let mut diffs_written = 0usize;
    let mut runs: Vec<(SceneSummary, CompareReport)> = Vec::new();
    for (scene_index, spec) in a.scene.iter().enumerate() {
        let scene = scene::load(spec)?;
        let cameras = scene::path(&a.frames.path, &scene)?;
        let progress = Progress::bar(cameras.len() as u64, format!("{spec}: preparing"));
        let mut diff_error = None;
        let report = compare(scene.scene.clone(), &cameras, &config, &mut |event| match event {
            CompareProgress::Building { label, .. } => progress.set_message(format!("{spec}: preparing {label}")),
            CompareProgress::Built { .. } => progress.set_message(format!("{spec}: rendering")),
            CompareProgress::Differs { label, index, image } => {
                let Some(dir) = &a.diff_out else { return };
                let prefix = if several {
                    format!("scene{scene_index}-")
                } else {
                    String::new()
                };
                let path = dir.join(format!("{prefix}{}-frame_{index:05}.png", file_label(label)));
                if diff_error.is_none() {
                    match image.save_with_format(&path, image::ImageFormat::Png) {
                        Ok(()) => diffs_written += 1,
                        Err(e) => diff_error = Some(anyhow::anyhow!("cannot write '{}': {e}", path.display())),
                    }
                }
            }
            CompareProgress::Frame { .. } => progress.inc(),
        })
        .with_context(|| format!("comparing on scene '{spec}'"))?;
        drop(progress);
        if let Some(e) = diff_error {
            return Err(e);
        }
        let summary = scene.summary();
        say_raw!("{}", report_text(&summary, &a.frames.path.text, &report));
        runs.push((summary, report));
    }

    if let Some(p) = &a.json {
        let out = CompareOut {
            tool: "occult",
            version: env!("CARGO_PKG_VERSION"),
            path: &a.frames.path.text,
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
        let header = csv_header(&runs);
        let header: Vec<&str> = header.iter().map(String::as_str).collect();
        output::write_csv(p, &header, &csv_rows(&runs))?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.plot {
        // Checked before the run; a counter some renderers report only in some configurations
        // may still be missing from this one.
        let reported = PLOT_Y_FIXED.contains(&a.plot_y.as_str())
            || runs.iter().any(|(_, r)| {
                r.renderers
                    .iter()
                    .any(|x| x.stats.counters.contains_key(a.plot_y.as_str()))
            });
        if !reported {
            bail!(
                "--plot-y {}: no renderer reported this counter in this run (it depends on their settings)",
                a.plot_y
            );
        }
        let panels: Vec<Panel> = runs
            .iter()
            .map(|(s, r)| frame_panel(s, &a.frames.path.text, r, &a.plot_y))
            .collect();
        plot::draw(p, &panels)?;
        say!("wrote {}", p.display());
    }
    for (axis, p) in &scaling_plots {
        if let Some(p) = p {
            plot::draw(p, &[scaling_panel(&a.frames.path.text, &runs, *axis)])?;
            say!("wrote {}", p.display());
        }
    }
    if let Some(dir) = &a.diff_out {
        say!(
            "wrote {diffs_written} images of differing frames to {} (red: wrong by the paper's criterion, yellow: another item visible through the pixel)",
            dir.display()
        );
    }
    Ok(())
}

/// A renderer label as part of a file name: characters other than letters, digits, `.`, `_`
/// and `-` become `_`.
fn file_label(label: &str) -> String {
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// What `--plot-y` takes besides counter names.
const PLOT_Y_FIXED: [&str; 3] = ["time", "submitted", "rasterized"];

/// Refuses a `--plot-y` that is neither a fixed quantity nor a counter any renderer of the
/// line-up (the reference included) can report.
fn check_plot_y(a: &CompareArgs) -> Result<()> {
    if PLOT_Y_FIXED.contains(&a.plot_y.as_str()) {
        return Ok(());
    }
    let mut lineup: Vec<&AlgoSpec> = a.algos.0.iter().collect();
    if let Reference::Spec(r) = &a.reference.0 {
        lineup.push(r);
    }
    let known = counter_names(lineup);
    if !known.contains(&a.plot_y.as_str()) {
        bail!(
            "--plot-y {}: not time, submitted, rasterized or a counter of these renderers ({})",
            a.plot_y,
            output::names_or_none(&known)
        );
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
        "path {path}: {} frames at {}x{}, {} threads; reference {}\n",
        r.frames, r.width, r.height, r.threads, r.reference_note
    );
    let im = &r.image;
    out += &format!(
        "image (on {}): {} covered pixels per frame",
        im.measured_on,
        output::count(im.mean_covered_pixels())
    );
    if let (Some(p), Some(dc)) = (&im.projected_pixels, im.mean_depth_complexity()) {
        let mean_p = p.iter().sum::<f64>() / p.len().max(1) as f64;
        out += &format!(
            ", image complexity {} pixels, depth complexity {dc:.2}",
            output::count(mean_p)
        );
    }
    out += "\n\n";
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
        "peak RSS",
    ];
    let mut rows: Vec<Vec<String>> = r
        .renderers
        .iter()
        .map(|x| {
            let mut name = x.name.to_string();
            if x.is_reference {
                name.push_str(" (ref)");
            }
            let error = if x.frames_identical.is_none_or(|n| n == x.frames) {
                "-".to_string()
            } else {
                let psnr = x.min_psnr_db.map_or(String::new(), |p| format!(", {p:.1} dB"));
                format!(
                    "{:.3}% (paper {:.3}%){psnr}",
                    100.0 * x.mean_item_error,
                    100.0 * x.mean_paper_error
                )
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
                identical_text(x),
                error,
                output::millis(x.prepare_ms),
                output::bytes(x.memory_bytes as u64),
                x.peak_rss_bytes.map_or("-".into(), output::bytes),
            ]
        })
        .collect();
    if let Some(o) = &r.oracle {
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
            "-".into(),
        ]);
    }
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
    if let Some(reference) = &r.reference {
        for x in &r.renderers {
            let identical = x.frames_identical.unwrap_or(x.frames);
            if x.conservative && identical < x.frames {
                out += &format!(
                    "WARNING: {} is conservative but {} of {} frames differ from {reference} (DESIGN invariant 2)\n",
                    x.name,
                    x.frames - identical,
                    x.frames,
                );
            }
        }
    }
    if let Some(o) = r.oracle.as_ref().filter(|o| o.frames_identical < r.frames) {
        out += &format!(
            "WARNING: rasterizing the visible set reproduced only {} of {} reference frames\n",
            o.frames_identical, r.frames
        );
    }
    if r.renderers.iter().any(|x| x.peak_rss_bytes.is_some()) {
        out += "peak RSS: the whole process while that renderer was built and rendered (the scene and the other renderers' structures included)\n";
    }
    if let Some(rss) = r.process_peak_rss_bytes {
        out += &format!(
            "process peak RSS (whole process, all renderers and the scene): {}\n",
            output::bytes(rss)
        );
    }
    out
}

/// `frames identical/frames`, or `-` when nothing was checked.
pub fn identical_text(x: &RendererReport) -> String {
    x.frames_identical
        .map_or_else(|| "-".into(), |n| format!("{n}/{}", x.frames))
}

/// The CSV header: the fixed columns, then every renderer counter seen in `runs`.
fn csv_header(runs: &[(SceneSummary, CompareReport)]) -> Vec<String> {
    let mut header: Vec<String> = CSV_HEADER.iter().map(|s| s.to_string()).collect();
    header.extend(reported_counters(runs).into_iter().map(str::to_string));
    header
}

/// Every renderer counter of `runs`, sorted.
fn reported_counters(runs: &[(SceneSummary, CompareReport)]) -> Vec<&'static str> {
    let mut names: Vec<&'static str> = runs
        .iter()
        .flat_map(|(_, r)| r.renderers.iter())
        .flat_map(|x| x.stats.counters.keys().copied())
        .collect();
    names.sort_unstable();
    names.dedup();
    names
}

fn csv_rows(runs: &[(SceneSummary, CompareReport)]) -> Vec<Vec<String>> {
    let counters = reported_counters(runs);
    let mut rows = Vec::new();
    for (scene, r) in runs {
        let im = &r.image;
        let image_fields = |i: usize| {
            [
                im.covered_pixels[i].to_string(),
                im.projected_pixels
                    .as_ref()
                    .map_or(String::new(), |p| format!("{}", p[i])),
            ]
        };
        for x in &r.renderers {
            for (i, f) in x.per_frame.iter().enumerate() {
                let mut row = vec![
                    scene.spec.clone(),
                    scene.triangles.to_string(),
                    x.name.to_string(),
                    i.to_string(),
                    format!("{}", f.time_ms),
                    f.triangles_submitted.to_string(),
                    f.triangles_rasterized.to_string(),
                    im.triangles_visible[i].to_string(),
                    if r.reference.is_some() {
                        f.identical.to_string()
                    } else {
                        String::new()
                    },
                    opt_field(f.item_error),
                    opt_field(f.paper_error),
                    opt_field(f.psnr_db),
                ];
                row.extend(image_fields(i));
                row.push(opt_field(x.peak_rss_bytes));
                row.extend(counters.iter().map(|&c| {
                    if f.counters.0.iter().any(|(k, _)| *k == c) {
                        f.counters.get(c).to_string()
                    } else {
                        String::new()
                    }
                }));
                rows.push(row);
            }
        }
        if let Some(o) = &r.oracle {
            for (i, (&t, &v)) in o.per_frame_ms.iter().zip(&o.triangles_visible).enumerate() {
                let mut row = vec![
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
                ];
                row.extend(image_fields(i));
                row.push(String::new());
                row.extend(counters.iter().map(|_| String::new()));
                rows.push(row);
            }
        }
    }
    rows
}

/// One scene's per-frame plot of `what` (see `--plot-y`).
fn frame_panel(scene: &SceneSummary, path: &str, r: &CompareReport, what: &str) -> Panel {
    let value = |f: &FrameRecord| -> Option<f64> {
        match what {
            "time" => Some(f.time_ms),
            "submitted" => Some(f.triangles_submitted as f64),
            "rasterized" => Some(f.triangles_rasterized as f64),
            counter => f.counters.0.iter().find(|(k, _)| *k == counter).map(|&(_, v)| v as f64),
        }
    };
    let mean_of = |points: &[(f64, f64)]| points.iter().map(|p| p.1).sum::<f64>() / points.len().max(1) as f64;
    let mut series: Vec<Series> = r
        .renderers
        .iter()
        .filter_map(|x| {
            let points: Vec<(f64, f64)> = x
                .per_frame
                .iter()
                .enumerate()
                .filter_map(|(i, f)| Some((i as f64, value(f)?)))
                .collect();
            let mean = match what {
                "time" => format!("mean {} ms", output::millis(x.mean_ms)),
                _ if points.is_empty() => return None,
                _ => format!("mean {}", output::count(mean_of(&points))),
            };
            Some(Series {
                name: format!("{} ({mean})", x.name),
                points,
                dashed: false,
            })
        })
        .collect();
    match (what, &r.oracle) {
        ("time", Some(o)) => series.push(Series {
            name: format!("oracle: visible triangles only (mean {} ms)", output::millis(o.mean_ms)),
            points: o.per_frame_ms.iter().enumerate().map(|(i, &t)| (i as f64, t)).collect(),
            dashed: true,
        }),
        ("submitted" | "rasterized", _) => {
            let points: Vec<(f64, f64)> = r
                .image
                .triangles_visible
                .iter()
                .enumerate()
                .map(|(i, &v)| (i as f64, v as f64))
                .collect();
            series.push(Series {
                name: format!(
                    "visible on {} (mean {})",
                    r.image.measured_on,
                    output::count(mean_of(&points))
                ),
                points,
                dashed: true,
            });
        }
        _ => {}
    }
    let y_label = match what {
        "time" => "frame time (ms, log)".to_string(),
        "submitted" => "triangles submitted per frame (log)".to_string(),
        "rasterized" => "triangles rasterized per frame (log)".to_string(),
        counter => format!("{counter} per frame (log)"),
    };
    Panel {
        title: format!(
            "{} ({} triangles), path {path}, {}x{}",
            scene.spec,
            output::count(scene.triangles as f64),
            r.width,
            r.height
        ),
        x_label: "frame".into(),
        y_label,
        log_x: false,
        integer_x: true,
        series,
    }
}

/// The x axis of `--plot-scaling`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ScalingAxis {
    Triangles,
    Covered,
    Image,
    Depth,
}

impl ScalingAxis {
    /// From the `--plot-scaling-x` value (clap has checked it).
    fn parse(s: &str) -> Self {
        match s {
            "covered" => Self::Covered,
            "image" => Self::Image,
            "depth" => Self::Depth,
            _ => Self::Triangles,
        }
    }

    /// The file of this axis's plot when several are drawn: `F.png` → `F-<axis>.png`.
    fn file_for(self, path: &Path) -> PathBuf {
        let stem = path.file_stem().map(|s| s.to_string_lossy()).unwrap_or_default();
        let name = match path.extension() {
            Some(ext) => format!("{stem}-{}.{}", self.key(), ext.to_string_lossy()),
            None => format!("{stem}-{}", self.key()),
        };
        path.with_file_name(name)
    }

    /// The `--plot-scaling-x` value naming this axis.
    fn key(self) -> &'static str {
        match self {
            Self::Triangles => "triangles",
            Self::Covered => "covered",
            Self::Image => "image",
            Self::Depth => "depth",
        }
    }

    fn needs_image_complexity(self) -> bool {
        matches!(self, Self::Image | Self::Depth)
    }

    /// The x value of one scene's run.
    fn value(self, scene: &SceneSummary, r: &CompareReport) -> Option<f64> {
        let im = &r.image;
        match self {
            Self::Triangles => Some(scene.triangles as f64),
            Self::Covered => Some(im.mean_covered_pixels()),
            Self::Image => im
                .projected_pixels
                .as_ref()
                .map(|p| p.iter().sum::<f64>() / p.len().max(1) as f64),
            Self::Depth => im.mean_depth_complexity(),
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::Triangles => "scene size (triangle instances, log)",
            Self::Covered => "covered pixels per frame",
            Self::Image => "image complexity (screen area of all triangles in view, pixels)",
            Self::Depth => "depth complexity (image complexity / covered pixels)",
        }
    }

    fn title(self) -> &'static str {
        match self {
            Self::Triangles => "scene size",
            Self::Covered => "covered pixels",
            Self::Image => "image complexity",
            Self::Depth => "depth complexity",
        }
    }
}

fn scaling_panel(path: &str, runs: &[(SceneSummary, CompareReport)], axis: ScalingAxis) -> Panel {
    let mut names: Vec<&str> = Vec::new();
    for (_, r) in runs {
        for x in &r.renderers {
            if !names.contains(&x.name.as_str()) {
                names.push(&x.name);
            }
        }
    }
    // Points sorted by x, so lines join neighbours along the axis.
    let sorted = |mut points: Vec<(f64, f64)>| {
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        points
    };
    let mut series: Vec<Series> = names
        .iter()
        .map(|&name| Series {
            name: name.to_string(),
            points: sorted(
                runs.iter()
                    .filter_map(|(s, r)| Some((axis.value(s, r)?, r.renderer(name)?.mean_ms)))
                    .collect(),
            ),
            dashed: false,
        })
        .collect();
    if runs.iter().any(|(_, r)| r.oracle.is_some()) {
        series.push(Series {
            name: "oracle: visible triangles only".into(),
            points: sorted(
                runs.iter()
                    .filter_map(|(s, r)| Some((axis.value(s, r)?, r.oracle.as_ref()?.mean_ms)))
                    .collect(),
            ),
            dashed: true,
        });
    }
    let (w, h) = runs.first().map_or((0, 0), |(_, r)| (r.width, r.height));
    Panel {
        title: format!("mean frame time against {}, path {path}, {w}x{h}", axis.title()),
        x_label: axis.label().into(),
        y_label: "mean frame time (ms, log)".into(),
        log_x: true,
        integer_x: false,
        series,
    }
}
