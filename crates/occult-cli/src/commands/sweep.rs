//! `occult sweep`: one renderer parameter varied over a list of values, a full comparison per
//! value (same scene, path and frame size), and the mean frame time and chosen counters plotted
//! against the value: the figures of the papers that put a parameter on the x axis (grid
//! resolution, depth accuracy ε, leaf size...).

use anyhow::{bail, Result};
use occult_harness::compare::{CompareProgress, CompareReport};
use occult_harness::sweep::{counter_names, sweep, SweepConfig, SweepError, Vary};
use occult_render::RenderOptions;
use serde::Serialize;

use crate::args::SweepArgs;
use crate::commands::compare::identical_text;
use crate::output;
use crate::plot::{self, Panel, Series};
use crate::progress::Progress;
use crate::scene::{self, SceneSummary};

/// Parses `algo.key=v1,v2,...`; every value must be a finite number (it is the x axis).
pub fn parse_vary(s: &str) -> Result<Vary, String> {
    let bad = || format!("expected ALGO.KEY=V1,V2,... (for example oqgrid.res=10,20,40), not '{s}'");
    let (target, values) = s.split_once('=').ok_or_else(bad)?;
    let (algorithm, key) = target.trim().split_once('.').ok_or_else(bad)?;
    let values: Vec<String> = values.split(',').map(|v| v.trim().to_string()).collect();
    if algorithm.is_empty() || key.is_empty() || values.iter().any(String::is_empty) {
        return Err(bad());
    }
    for v in &values {
        if !v.parse::<f64>().is_ok_and(f64::is_finite) {
            return Err(format!(
                "--vary values are plotted on the x axis and must be numbers, not '{v}'"
            ));
        }
    }
    Ok(Vary {
        algorithm: algorithm.to_string(),
        key: key.to_string(),
        values,
    })
}

#[derive(Serialize)]
struct SweepOut<'a> {
    tool: &'static str,
    version: &'static str,
    scene: SceneSummary,
    path: &'a str,
    vary: String,
    points: Vec<PointOut<'a>>,
}

#[derive(Serialize)]
struct PointOut<'a> {
    value: &'a str,
    #[serde(flatten)]
    report: &'a CompareReport,
}

/// Runs the command.
pub fn run(a: SweepArgs) -> Result<()> {
    output::check_outputs([&a.json, &a.csv, &a.plot])?;
    let vary = &a.vary;
    let config = SweepConfig {
        algorithms: a.algos.0.clone(),
        vary: vary.clone(),
        options: RenderOptions::default(),
        width: a.frames.size.width,
        height: a.frames.size.height,
        reference: a.reference.0.clone(),
    };
    // Every value is checked before the scene is built.
    match config.lineups() {
        Err(SweepError::NotInLineup { algorithm, lineup }) => {
            bail!("--vary names '{algorithm}', which is not in --algos ({lineup})")
        }
        other => other?,
    };
    let known = counter_names(&a.algos.0);
    for c in &a.counter {
        if !known.contains(&c.as_str()) {
            bail!(
                "--counter {c}: not a counter of {} ({})",
                config.lineup_text(),
                output::names_or_none(&known)
            );
        }
    }
    let scene = scene::load(&a.scene)?;
    let cameras = scene::path(&a.frames.path, &scene)?;
    let total = (cameras.len() * vary.values.len()) as u64;
    let progress = Progress::bar(total, format!("{}: preparing", a.scene));
    let report = sweep(&scene.scene, &cameras, &config, &mut |(value, event)| match event {
        CompareProgress::Building { label, .. } => {
            progress.set_message(format!("{}={value}: preparing {label}", vary.key))
        }
        CompareProgress::Built { .. } => progress.set_message(format!("{}={value}: rendering", vary.key)),
        CompareProgress::Frame { .. } => progress.inc(),
        CompareProgress::Differs { .. } => {} // not requested by the sweep
    })?;
    drop(progress);
    let reports: Vec<&CompareReport> = report.points.iter().map(|p| &p.report).collect();
    let summary = scene.summary();
    let vary_text = format!("{}.{}", vary.algorithm, vary.key);

    // The table: one row per value and renderer.
    let mut header = vec![
        vary_text.as_str(),
        "renderer",
        "mean ms",
        "p95 ms",
        "vs zbuffer",
        "rasterized/frame",
        "visible/frame",
        "identical",
        "prepare ms",
    ];
    header.extend(a.counter.iter().map(String::as_str));
    let mut rows = Vec::new();
    for (value, r) in vary.values.iter().zip(&reports) {
        for x in &r.renderers {
            let mut row = vec![
                value.clone(),
                x.name.clone(),
                output::millis(x.mean_ms),
                output::millis(x.p95_ms),
                x.speedup_vs_zbuffer.map_or("-".into(), |s| format!("{s:.2}x")),
                output::count(x.triangles_rasterized),
                output::count(x.triangles_visible),
                identical_text(x),
                output::millis(x.prepare_ms),
            ];
            row.extend(a.counter.iter().map(|c| {
                x.stats
                    .counters
                    .get(c.as_str())
                    .map_or("-".into(), |v| output::count(*v))
            }));
            rows.push(row);
        }
    }
    say_raw!(
        "\n{}; varying {vary_text}\n\n{}",
        summary.walk_line(&a.frames, cameras.len()),
        output::table(&header, &rows)
    );

    if let Some(p) = &a.json {
        let out = SweepOut {
            tool: "occult",
            version: env!("CARGO_PKG_VERSION"),
            scene: summary.clone(),
            path: &a.frames.path.text,
            vary: vary_text.clone(),
            points: vary
                .values
                .iter()
                .zip(&reports)
                .map(|(value, &report)| PointOut { value, report })
                .collect(),
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.csv {
        output::write_csv(p, &header, &rows)?;
        say!("wrote {}", p.display());
    }
    if let Some(p) = &a.plot {
        let series_of = |y: &dyn Fn(&occult_harness::compare::RendererReport) -> Option<f64>| -> Vec<Series> {
            report
                .lines(vary, y)
                .into_iter()
                .map(|l| Series {
                    name: l.name,
                    points: l.points,
                    dashed: false,
                })
                .collect()
        };
        let title = format!("{} — {}, {} frames", summary.label(), a.frames.path, cameras.len());
        let mut panels = vec![Panel {
            title: title.clone(),
            x_label: vary_text.clone(),
            y_label: "mean frame time (ms, log)".into(),
            log_x: a.log_x,
            integer_x: false,
            series: series_of(&|x| Some(x.mean_ms)),
        }];
        for c in &a.counter {
            panels.push(Panel {
                title: format!("{c} per frame"),
                x_label: vary_text.clone(),
                y_label: format!("{c} (log)"),
                log_x: a.log_x,
                integer_x: false,
                series: series_of(&|x| x.stats.counters.get(c.as_str()).copied()),
            });
        }
        plot::draw(p, &panels)?;
        say!("wrote {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vary_parses_and_refuses() {
        let v = parse_vary("oqgrid.res=10, 20,40").expect("a renderer, key and spaced values parse");
        assert_eq!((v.algorithm.as_str(), v.key.as_str()), ("oqgrid", "res"));
        assert_eq!(v.values, ["10", "20", "40"]);
        for bad in [
            "oqgrid.res",
            "res=1,2",
            "oqgrid.res=1,,2",
            "oqgrid.res=a,b",
            ".res=1",
            "oqgrid.=1",
        ] {
            assert!(parse_vary(bad).is_err(), "{bad}");
        }
    }
}
