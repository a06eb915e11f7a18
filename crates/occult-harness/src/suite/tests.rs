//! The runner on tiny case lists: summaries, violations, skipped and failing cases.

use super::*;
use occult_render::Algorithm;

/// Two small generated cases, fast on two cores.
const TINY: [Case; 2] = [
    Case {
        name: "tiny-city-street",
        scene: CaseScene::Generated("city:blocks=1,detail=1,variants=2"),
        path: "street",
        frames: 2,
        quick: true,
    },
    Case {
        name: "tiny-terrain-orbit",
        scene: CaseScene::Generated("terrain:g=8"),
        path: "circle",
        frames: 3,
        quick: false,
    },
];

const CUBE_CASE: Case = Case {
    name: "cube-orbit",
    scene: CaseScene::Model("cube/cube.obj"),
    path: "circle",
    frames: 2,
    quick: false,
};

fn config<A: Into<AlgoSpec>>(algorithms: impl IntoIterator<Item = A>) -> SuiteConfig {
    let mut config = SuiteConfig::new(algorithms, 48, 32);
    config.options.raster.threads = 2;
    config
}

/// A fresh directory for one test's files.
fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("occult-suite-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the temporary directory is writable");
    dir
}

#[test]
fn every_renderer_is_summarised_over_every_case() {
    let mut events = Vec::new();
    let report = run_suite(&TINY, &config(Algorithm::all()), &mut |e| {
        events.push(match e {
            SuiteProgress::Case { case, .. } => format!("case {}", case.name),
            SuiteProgress::Compare { .. } => "compare".to_string(),
            SuiteProgress::Skipped(s) => format!("skipped {}", s.name),
            SuiteProgress::Done(c) => format!("done {}", c.name),
        })
    })
    .expect("the tiny cases run with every renderer");
    assert_eq!(report.suite_version, SUITE_VERSION);
    assert_eq!((report.width, report.height), (48, 32));
    assert_eq!(report.cases.len(), 2);
    assert!(report.skipped.is_empty());
    assert_eq!(report.cases[1].path, "circle:3");
    assert_eq!(report.cases[1].frames, 3);
    assert_eq!(report.cases[1].triangles, 2 * 8 * 8);
    let names: Vec<&str> = report.summary.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, Algorithm::all().iter().map(|a| a.name()).collect::<Vec<_>>());
    for r in &report.summary {
        assert_eq!(r.cases, 2, "{}", r.name);
        assert_eq!(r.frames, 5);
        assert!(r.speedup_geomean.is_some_and(|s| s > 0.0), "{}", r.name);
        assert!(r.oracle_geomean.is_some_and(|s| s > 0.0), "{}", r.name);
        let worst = r
            .speedup_worst
            .as_ref()
            .expect("a renderer timed on two cases has a worst case");
        assert!(worst.case.starts_with("tiny-"));
        assert!(
            worst.value
                <= r.speedup_geomean
                    .expect("a renderer timed on two cases has a mean speedup")
                    * (1.0 + 1e-12)
        );
        assert!(
            r.oracle_worst
                .as_ref()
                .expect("a renderer checked on two cases has a worst case")
                .value
                >= r.oracle_geomean
                    .expect("a renderer checked on two cases has a mean ratio to the oracle")
                    * (1.0 - 1e-12)
        );
        if r.conservative {
            assert_eq!(r.frames_identical, Some(5), "{}: DESIGN invariant 2", r.name);
        }
    }
    for case in &report.cases {
        for r in &case.renderers {
            let direct = case
                .compare
                .renderers
                .iter()
                .find(|c| c.name == r.name)
                .expect("every renderer compared")
                .per_frame
                .iter()
                .filter(|f| f.counters.get("payoff_direct") == 1)
                .count();
            assert_eq!(r.direct_frames, direct, "{} on {}", r.name, case.name);
        }
        // Only renderers that cull can draw a frame directly instead.
        let never = ["zbuffer", "frustum", "rzb"];
        assert!(case
            .renderers
            .iter()
            .all(|r| r.direct_frames == 0 || !never.contains(&r.name.as_str())));
    }
    let zbuffer = report.renderer("zbuffer").expect("zbuffer is in the summary");
    assert_eq!(zbuffer.speedup_geomean, Some(1.0));
    assert_eq!(zbuffer.violations, 0);
    // Only speed can be violated here: conservative frames are identical.
    assert!(report
        .violations
        .iter()
        .all(|v| v.kind == ViolationKind::SlowerThanZbuffer
            && v.speedup_vs_zbuffer.expect("a speed violation names its speedup") < 1.0));
    assert!(report.violations.iter().all(|v| v.renderer != "rzb"));
    assert_eq!(report.violation_count, report.violations.len());
    assert_eq!(
        report.violation_count,
        report.summary.iter().map(|r| r.violations).sum::<usize>()
    );
    assert_eq!(
        events.first().expect("the suite reports its first case"),
        "case tiny-city-street"
    );
    assert_eq!(
        events.last().expect("the suite reports that it is done"),
        "done tiny-terrain-orbit"
    );
    assert!(events.contains(&"compare".to_string()));
    let json = serde_json::to_value(&report).expect("a report serialises to JSON");
    for field in [
        "suite_version",
        "cases",
        "summary",
        "violations",
        "violation_count",
        "skipped",
    ] {
        assert!(json.get(field).is_some(), "{field}");
    }
    assert_eq!(json["cases"][0]["scene"]["kind"], "generated");
    assert_eq!(json["cases"][0]["runs"], 1);
    assert!(json["cases"][0].get("more_runs").is_none(), "one run: no other runs");
}

/// Repeated cases: every run builds and renders afresh; the figures pool the runs, the
/// interval holds each run's speedup, and the report keeps every run's comparison.
#[test]
fn repeated_cases_pool_their_runs() {
    let mut c = config([Algorithm::FRUSTUM]);
    c.repeats = 3;
    let mut runs_seen = Vec::new();
    let report = run_suite(&TINY[1..], &c, &mut |e| {
        if let SuiteProgress::Compare {
            run,
            event: crate::compare::CompareProgress::Built { .. },
            ..
        } = e
        {
            runs_seen.push(run);
        }
    })
    .expect("the tiny terrain case runs three times");
    assert!((0..3).all(|run| runs_seen.contains(&run)) && !runs_seen.contains(&3));
    let case = &report.cases[0];
    assert_eq!((case.runs, case.more_runs.len(), case.frames), (3, 2, 3));
    let all: Vec<&crate::compare::CompareReport> = std::iter::once(&case.compare).chain(&case.more_runs).collect();
    let mean = |c: &crate::compare::CompareReport, name: &str| c.renderer(name).expect("compared").mean_ms;
    let frustum = case.renderer("frustum").expect("frustum is in the case's report");
    assert_eq!(frustum.frames, 9);
    assert_eq!(frustum.frames_identical, Some(9), "DESIGN invariant 2, every run");
    let own: Vec<f64> = all
        .iter()
        .map(|c| {
            c.renderer("frustum")
                .and_then(|r| r.speedup_vs_zbuffer)
                .expect("each run measures frustum against zbuffer")
        })
        .collect();
    assert_eq!(frustum.speedup_runs, own);
    let pooled =
        all.iter().map(|c| mean(c, "zbuffer")).sum::<f64>() / all.iter().map(|c| mean(c, "frustum")).sum::<f64>();
    let speedup = frustum.speedup_vs_zbuffer.expect("pooled over the runs");
    assert!((speedup - pooled).abs() <= 1e-12 * pooled, "{speedup} {pooled}");
    let [lo, hi] = frustum.speedup_interval.expect("nine frames");
    assert!(own.iter().all(|s| (lo..=hi).contains(s)), "{lo} {hi} {own:?}");
    let oracle: f64 = all
        .iter()
        .map(|c| c.oracle.as_ref().expect("each run has the oracle").mean_ms)
        .sum();
    assert_eq!(case.oracle_ms, Some(oracle / 3.0));
    let vs_oracle = frustum.vs_oracle.expect("pooled over the runs");
    assert!((vs_oracle - 3.0 * frustum.mean_ms / oracle).abs() <= 1e-9 * vs_oracle);
    assert_eq!(report.renderer("frustum").expect("in the summary").frames, 9);
    let zbuffer = case.renderer("zbuffer").expect("zbuffer is in the case's report");
    assert_eq!(zbuffer.speedup_vs_zbuffer, Some(1.0), "exactly, whatever the rounding");
    assert!(zbuffer.violations().is_empty());
    let json = serde_json::to_value(&report).expect("a report serialises to JSON");
    assert_eq!(json["cases"][0]["more_runs"].as_array().map(Vec::len), Some(2));

    c.repeats = 0;
    assert!(matches!(
        run_suite(&TINY[1..], &c, &mut |_| {}),
        Err(SuiteError::NoRuns)
    ));
}

#[test]
fn zbuffer_is_measured_although_not_requested() {
    let report = run_suite(&TINY[1..], &config([Algorithm::FRUSTUM]), &mut |_| {})
        .expect("the tiny terrain case runs with frustum");
    assert_eq!(report.algorithms, ["frustum"]);
    let case = &report.cases[0];
    assert_eq!(case.reference.as_deref(), Some("zbuffer"));
    assert!(case
        .renderer("frustum")
        .expect("frustum is in the case's report")
        .speedup_vs_zbuffer
        .is_some());
    assert!(case.oracle_ms.is_some());
}

#[test]
fn model_cases_are_skipped_without_their_file_and_run_with_it() {
    // No models folder: skipped, saying so.
    let report = run_suite(&[CUBE_CASE], &config([Algorithm::ZBUFFER]), &mut |_| {})
        .expect("a suite without models skips its model cases");
    assert!(report.cases.is_empty());
    assert_eq!(report.skipped[0].name, "cube-orbit");
    assert_eq!(report.skipped[0].path, None);
    assert_eq!(report.summary, []);
    assert_eq!(report.violation_count, 0);

    // A folder without the file: skipped, with the path looked for.
    let dir = scratch("models");
    let mut c = config([Algorithm::ZBUFFER, Algorithm::FRUSTUM]);
    c.models = Some(dir.clone());
    let cases = [CUBE_CASE, TINY[1]];
    let report = run_suite(&cases, &c, &mut |_| {}).expect("a suite with a models folder skips missing files");
    assert_eq!(report.cases.len(), 1);
    let skipped = &report.skipped[0];
    assert!(
        skipped
            .path
            .as_ref()
            .expect("a missing model names the path looked for")
            .ends_with("cube.obj"),
        "{skipped:?}"
    );
    assert!(skipped.reason.contains("missing"));

    // With the file.
    std::fs::create_dir_all(dir.join("cube")).expect("the temporary directory is writable");
    let mut obj = String::new();
    for i in 0..8 {
        obj += &format!("v {} {} {}\n", i & 1, i >> 1 & 1, i >> 2 & 1);
    }
    obj += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
    std::fs::write(dir.join("cube/cube.obj"), obj).expect("the temporary directory is writable");
    let report = run_suite(&cases, &c, &mut |_| {}).expect("the cube model and the tiny terrain case run");
    assert_eq!(report.cases.len(), 2);
    assert!(report.skipped.is_empty());
    assert_eq!(report.cases[0].triangles, 12);
    assert_eq!(report.cases[0].scene_name, "cube.obj");
    assert_eq!(
        report
            .renderer("frustum")
            .expect("frustum is in the summary")
            .frames_identical,
        Some(5)
    );
    std::fs::remove_dir_all(&dir).expect("the test's scratch directory can be removed");
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let c = config([Algorithm::ZBUFFER]);
    assert!(matches!(run_suite(&[], &c, &mut |_| {}), Err(SuiteError::NoCases)));

    let mut unreadable = c.clone();
    unreadable.models = Some(PathBuf::from("/no/such/models/folder"));
    let e = run_suite(&TINY[1..], &unreadable, &mut |_| {}).unwrap_err();
    assert!(matches!(e, SuiteError::Models { .. }));
    assert!(e.to_string().contains("/no/such/models/folder"));

    let bad_scene = Case {
        scene: CaseScene::Generated("city:blocks=0"),
        ..TINY[0]
    };
    let e = run_suite(&[bad_scene], &c, &mut |_| {}).unwrap_err();
    assert!(matches!(e, SuiteError::Scene { .. }));
    assert!(e.to_string().contains("tiny-city-street"));

    let bad_path = Case {
        path: "spiral",
        ..TINY[1]
    };
    let e = run_suite(&[bad_path], &c, &mut |_| {}).unwrap_err();
    assert!(matches!(e, SuiteError::Path { .. }));
    assert!(e.to_string().contains("spiral:3"));
}
