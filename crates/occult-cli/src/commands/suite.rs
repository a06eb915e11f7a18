//! `occult suite`: the performance yardstick ([`occult_harness::suite`] runs it; this chooses
//! the cases, the size and the models folder, and writes the tables, JSON and chart).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Result};
use occult_harness::compare::CompareProgress;
use occult_harness::suite::{
    default_size, run_suite, select, Case, CaseRenderer, CaseReport, CaseScene, SuiteConfig, SuiteProgress,
    SuiteReport, ViolationKind, Worst, QUICK_MAX_FRAMES, SUITE_VERSION,
};
use occult_render::RenderOptions;
use serde::Serialize;

use crate::args::SuiteArgs;
use crate::output;
use crate::plot::{self, BarGroup, BarPanel};
use crate::progress::Progress;

/// The environment variable naming the models folder when `--models` is not given.
const MODELS_VAR: &str = "OCCULT_MODELS";

/// The models folder tried last, relative to the working directory.
const MODELS_FALLBACK: &str = "../shared/models";

/// What `--json` holds: the run's settings, then the harness's report inline.
#[derive(Serialize)]
struct SuiteOut<'a> {
    tool: &'static str,
    version: &'static str,
    quick: bool,
    #[serde(flatten)]
    report: &'a SuiteReport,
}

/// Runs the command.
pub fn run(a: SuiteArgs) -> Result<()> {
    let cases = select(a.cases.as_deref(), a.quick, a.frames)?;
    if a.list {
        say_raw!("{}", list_text(&cases, a.quick));
        return Ok(());
    }
    output::check_outputs([&a.json, &a.chart])?;
    let (width, height) = a.size.map_or_else(|| default_size(a.quick), |s| (s.width, s.height));
    let config = SuiteConfig {
        algorithms: a.algos.0.clone(),
        options: RenderOptions::default(),
        width,
        height,
        models: models_folder(a.models.clone()),
        repeats: a.repeat as usize,
    };
    say!(
        "suite v{SUITE_VERSION}{}: {} cases at {width}x{height}{}, renderers {}; models {}",
        if a.quick { " (quick)" } else { "" },
        cases.len(),
        if a.repeat > 1 {
            format!(", {} runs of each", a.repeat)
        } else {
            String::new()
        },
        config
            .algorithms
            .iter()
            .map(|a| a.label())
            .collect::<Vec<_>>()
            .join(", "),
        config.models.as_ref().map_or_else(
            || "none (model cases are skipped)".to_string(),
            |m| m.display().to_string()
        )
    );

    let mut bar: Option<Progress> = None;
    // Printing happens inside the progress callback, which cannot return an error: the first
    // one is kept and returned after the run.
    let mut print_error: Option<std::io::Error> = None;
    let mut print = |text: &str| {
        use std::io::Write as _;
        if print_error.is_none() {
            print_error = write!(std::io::stdout().lock(), "{text}").err();
        }
    };
    let report = run_suite(&cases, &config, &mut |event| match event {
        SuiteProgress::Case { case, index, count } => {
            bar = Some(Progress::bar(
                u64::from(case.frames) * u64::from(a.repeat),
                format!("[{}/{count}] {}: building the scene", index + 1, case.name),
            ));
        }
        SuiteProgress::Compare { case, run, event } => {
            if let Some(bar) = &bar {
                let run = if a.repeat > 1 {
                    format!(" (run {}/{})", run + 1, a.repeat)
                } else {
                    String::new()
                };
                match event {
                    CompareProgress::Building { label, .. } => {
                        bar.set_message(format!("{}{run}: preparing {label}", case.name))
                    }
                    CompareProgress::Built { .. } => bar.set_message(format!("{}{run}: rendering", case.name)),
                    CompareProgress::Frame { .. } => bar.inc(),
                    CompareProgress::Differs { .. } => {} // not requested by the suite
                }
            }
        }
        SuiteProgress::Skipped(s) => {
            bar = None;
            print(&format!(
                "\n{}: skipped, {}{}\n",
                s.name,
                s.reason,
                s.path.as_ref().map_or(String::new(), |p| format!(": {p}"))
            ));
        }
        SuiteProgress::Done(c) => {
            bar = None;
            print(&case_text(c));
        }
    })?;
    drop(bar);
    if let Some(e) = print_error {
        return Err(e.into());
    }
    say_raw!("{}", summary_text(&report));

    if let Some(p) = &a.json {
        let out = SuiteOut {
            tool: "occult",
            version: env!("CARGO_PKG_VERSION"),
            quick: a.quick,
            report: &report,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.chart {
        if report.cases.is_empty() {
            bail!("no case ran (all skipped): nothing to chart in '{}'", p.display());
        }
        plot::draw_bars(p, &chart_panels(&report))?;
        say!("wrote {}", p.display());
    }
    Ok(())
}

/// `--models`, else `$OCCULT_MODELS` when set and not empty, else [`MODELS_FALLBACK`] when it
/// is a folder; `None` when none applies.
fn models_folder(given: Option<PathBuf>) -> Option<PathBuf> {
    given
        .or_else(|| {
            std::env::var_os(MODELS_VAR)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        })
        .or_else(|| Some(PathBuf::from(MODELS_FALLBACK)).filter(|p| p.is_dir()))
}

/// `--list`: the cases a run with these options would measure.
fn list_text(cases: &[Case], quick: bool) -> String {
    let (w, h) = default_size(quick);
    let mut out = format!(
        "suite v{SUITE_VERSION}{}: {} cases at {w}x{h} by default{}\n\n",
        if quick { " (quick)" } else { "" },
        cases.len(),
        if quick {
            format!(", at most {QUICK_MAX_FRAMES} frames a case")
        } else {
            String::new()
        }
    );
    let rows: Vec<Vec<String>> = cases
        .iter()
        .map(|c| {
            vec![
                c.name.to_string(),
                match c.scene {
                    CaseScene::Generated(spec) => spec.to_string(),
                    CaseScene::Model(file) => format!("{file} (model)"),
                },
                c.path.to_string(),
                c.frames.to_string(),
                if c.quick { "yes" } else { "-" }.to_string(),
            ]
        })
        .collect();
    out += &output::table(&["case", "scene", "path", "frames", "quick"], &rows);
    out
}

/// A ratio as `1.23x`, or `-`; near 1 with three decimals (`0.998x`), so that a ratio just
/// below 1, a violation, never reads `1.00x`.
fn ratio(r: Option<f64>) -> String {
    match r {
        Some(r) if (0.995..1.005).contains(&r) && r != 1.0 => format!("{r:.3}x"),
        Some(r) => format!("{r:.2}x"),
        None => "-".into(),
    }
}

/// One case: a header line and the compact table, violations flagged.
fn case_text(c: &CaseReport) -> String {
    let visible = c.renderers.first().map_or(0.0, |r| r.triangles_visible);
    let mut out = format!(
        "\n{}: {} ({} triangles), {} at {}x{}{}, {} visible triangles a frame; reference {}, oracle {} ms; {:.1} s\n",
        c.name,
        c.scene_name,
        output::count(c.triangles as f64),
        c.path,
        c.compare.width,
        c.compare.height,
        if c.runs > 1 {
            format!(", {} runs", c.runs)
        } else {
            String::new()
        },
        output::count(visible),
        c.reference.as_deref().unwrap_or("none"),
        c.oracle_ms.map_or_else(|| "-".into(), output::millis),
        c.seconds
    );
    let rows: Vec<Vec<String>> = c
        .renderers
        .iter()
        .map(|r| {
            let flags: Vec<String> = r
                .violations()
                .iter()
                .map(|&v| match v {
                    ViolationKind::SlowerThanZbuffer if !r.significantly_slower() => format!("<< {v} (within noise)"),
                    v => format!("<< {v}"),
                })
                .collect();
            vec![
                if r.conservative {
                    r.name.clone()
                } else {
                    format!("{} (approx.)", r.name)
                },
                output::millis(r.mean_ms),
                ratio(r.speedup_vs_zbuffer),
                if r.speedup_runs.len() > 1 {
                    let runs: Vec<String> = r.speedup_runs.iter().map(|&s| format!("{s:.2}")).collect();
                    runs.join(" ")
                } else {
                    "-".into()
                },
                r.speedup_interval
                    .map_or_else(|| "-".into(), |[lo, hi]| format!("{lo:.2}-{hi:.2}")),
                ratio(r.vs_oracle),
                r.frames_identical
                    .map_or_else(|| "-".into(), |n| format!("{n}/{}", r.frames)),
                format!("{}/{}", r.direct_frames, r.frames),
                output::count(r.triangles_rasterized),
                flags.join(" "),
            ]
        })
        .collect();
    out += &output::table(
        &[
            "renderer",
            "ms",
            "x zbuffer",
            "runs",
            if c.runs > 1 {
                "90% interval, runs widened"
            } else {
                "90% interval"
            },
            "x oracle",
            "identical",
            "direct",
            "rasterized/frame",
            "",
        ],
        &rows,
    );
    out
}

/// The per-renderer summary, the violations and the skipped cases.
fn summary_text(r: &SuiteReport) -> String {
    let mut out = format!(
        "\nsummary over {} case{} (suite v{}, {}x{}, {} threads, {:.0} s):\n",
        r.cases.len(),
        if r.cases.len() == 1 { "" } else { "s" },
        r.suite_version,
        r.width,
        r.height,
        r.threads,
        r.seconds
    );
    let worst = |w: &Option<Worst>| -> [String; 2] {
        w.as_ref()
            .map_or_else(|| ["-".into(), "-".into()], |w| [ratio(Some(w.value)), w.case.clone()])
    };
    let rows: Vec<Vec<String>> = r
        .summary
        .iter()
        .map(|s| {
            let [speedup_worst, speedup_case] = worst(&s.speedup_worst);
            let [oracle_worst, oracle_case] = worst(&s.oracle_worst);
            vec![
                if s.conservative {
                    s.name.clone()
                } else {
                    format!("{} (approx.)", s.name)
                },
                ratio(s.speedup_geomean),
                speedup_worst,
                speedup_case,
                ratio(s.oracle_geomean),
                oracle_worst,
                oracle_case,
                s.frames_identical
                    .map_or_else(|| "-".into(), |n| format!("{n}/{}", s.frames)),
                if s.conservative {
                    format!("{} ({})", s.violations, s.significant_violations)
                } else {
                    "-".into()
                },
            ]
        })
        .collect();
    out += &output::table(
        &[
            "renderer",
            "x zbuffer geomean",
            "worst",
            "on",
            "x oracle geomean",
            "worst",
            "on",
            "identical",
            "violations (beyond noise)",
        ],
        &rows,
    );
    let _ = writeln!(
        out,
        "\nviolations (a conservative renderer slower than zbuffer, or with a frame not identical, on a case): {}, \
         {} beyond noise (frames that differ, or slower with the speedup's 90% interval, widened to every run's, wholly below 1)",
        r.violation_count, r.significant_violation_count
    );
    for s in r.summary.iter().filter(|s| s.violations > 0) {
        let cases: Vec<String> = r
            .violations
            .iter()
            .filter(|v| v.renderer == s.name)
            .map(|v| match v.kind {
                ViolationKind::SlowerThanZbuffer => format!(
                    "{} {}{}",
                    v.case,
                    ratio(v.speedup_vs_zbuffer),
                    if v.significant { " (beyond noise)" } else { "" }
                ),
                ViolationKind::FramesDiffer => format!(
                    "{} frames differ ({}/{} identical)",
                    v.case,
                    v.frames_identical.unwrap_or(0),
                    v.frames
                ),
            })
            .collect();
        let _ = writeln!(out, "  {}: {}", s.name, cases.join(", "));
    }
    for s in &r.skipped {
        let _ = writeln!(
            out,
            "skipped {}: {}{}",
            s.name,
            s.reason,
            s.path.as_ref().map_or(String::new(), |p| format!(": {p}"))
        );
    }
    out
}

/// The chart: per case, each renderer's speedup over zbuffer, then its ratio to the oracle.
fn chart_panels(r: &SuiteReport) -> Vec<BarPanel> {
    let series: Vec<String> = r.summary.iter().map(|s| s.name.clone()).collect();
    let panel = |title: String, y_label: &str, value: fn(&CaseRenderer) -> Option<f64>| BarPanel {
        title,
        y_label: y_label.to_string(),
        groups: r
            .cases
            .iter()
            .map(|c| BarGroup {
                label: c.name.clone(),
                values: series.iter().map(|name| c.renderer(name).and_then(value)).collect(),
            })
            .collect(),
        series: series.clone(),
        reference: 1.0,
    };
    let at = format!("suite v{}, {}x{}", r.suite_version, r.width, r.height);
    vec![
        panel(
            format!("speedup over zbuffer (higher is faster; {at})"),
            "zbuffer time / renderer time",
            |x| x.speedup_vs_zbuffer,
        ),
        panel(
            format!("time over the oracle (1 = perfect culling at no cost; {at})"),
            "renderer time / oracle time",
            |x| x.vs_oracle,
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratios_near_one_show_which_side_of_it_they_fall() {
        assert_eq!(ratio(Some(0.998)), "0.998x");
        assert_eq!(ratio(Some(1.0)), "1.00x");
        assert_eq!(ratio(Some(1.004)), "1.004x");
        assert_eq!(ratio(Some(0.5)), "0.50x");
        assert_eq!(ratio(Some(12.0)), "12.00x");
        assert_eq!(ratio(None), "-");
    }
}
