//! `occult suite` on one small generated case at a tiny size: the JSON's fields, the chart,
//! skipped model cases, `--list`, and the errors. Never the real suite.

use super::*;

/// The cheapest generated case of the suite, run with few frames at a tiny size.
const CASE: &str = "city-street";

#[test]
fn suite_reports_every_renderer_per_case_with_summary_and_violations() {
    let dir = scratch("suite");
    let models = dir.join("models");
    std::fs::create_dir_all(&models).unwrap();
    let (json, chart) = (dir.join("s.json"), dir.join("s.png"));
    let stdout = ok(&[
        "--threads",
        "2",
        "suite",
        "--quick",
        "--cases",
        &format!("{CASE},sponza-orbit"),
        "--size",
        "64x48",
        "--frames",
        "2",
        "--models",
        path_arg(&models),
        "--json",
        path_arg(&json),
        "--chart",
        path_arg(&chart),
    ]);
    assert!(
        stdout.contains("summary over 1 case ") && stdout.contains("violations"),
        "{stdout}"
    );
    assert!(stdout.contains("sponza-orbit: skipped"), "{stdout}");
    let report = read_json(&json);
    assert_eq!(report["quick"], true);
    assert!(report["suite_version"].as_u64().unwrap() >= 1);
    assert_eq!(
        (report["width"].as_u64(), report["height"].as_u64()),
        (Some(64), Some(48))
    );
    let case = &report["cases"][0];
    assert_eq!(case["name"], CASE);
    assert_eq!(case["path"], "street:2");
    assert_eq!(case["frames"], 2);
    assert_eq!(case["reference"], "zbuffer");
    let renderers = case["renderers"].as_array().unwrap();
    assert_eq!(
        renderers.len(),
        occult_render::Algorithm::all().len(),
        "every renderer by default"
    );
    for r in renderers {
        for field in [
            "name",
            "mean_ms",
            "speedup_vs_zbuffer",
            "vs_oracle",
            "frames_identical",
            "frames",
            "triangles_rasterized",
            "triangles_visible",
        ] {
            assert!(!r[field].is_null(), "{field} of {r}");
        }
        if r["conservative"] == true {
            assert_eq!(r["frames_identical"], 2, "{r}");
        }
    }
    assert!(case["compare"]["renderers"].is_array(), "the full comparison is kept");
    let summary = report["summary"].as_array().unwrap();
    assert_eq!(summary.len(), occult_render::Algorithm::all().len());
    for s in summary {
        for field in [
            "speedup_geomean",
            "speedup_worst",
            "oracle_geomean",
            "oracle_worst",
            "violations",
        ] {
            assert!(!s[field].is_null(), "{field} of {s}");
        }
    }
    let violations = report["violations"].as_array().unwrap();
    assert_eq!(report["violation_count"].as_u64(), Some(violations.len() as u64));
    for v in violations {
        assert_eq!(
            v["kind"], "slower_than_zbuffer",
            "conservative frames are identical: {v}"
        );
        assert!(stdout.contains("<< slower than zbuffer"), "flagged in the table");
    }
    let skipped = &report["skipped"][0];
    assert_eq!(skipped["name"], "sponza-orbit");
    assert!(skipped["path"].as_str().unwrap().ends_with("sponza.obj"), "{skipped}");
    assert!(image::open(&chart).unwrap().width() >= 1100);
}

#[test]
fn suite_lists_its_cases() {
    let all = ok(&["suite", "--list"]);
    assert!(all.starts_with("suite v"), "{all}");
    for name in [
        CASE,
        "city32-street",
        "terrain-flyover",
        "lost-empire-orbit",
        "sponza-orbit",
    ] {
        assert!(all.contains(name), "{name}: {all}");
    }
    let quick = ok(&["suite", "--quick", "--list"]);
    assert!(quick.contains(CASE) && !quick.contains("city32-street"), "{quick}");
    let picked = ok(&["suite", "--list", "--cases", "terrain-flyover", "--frames", "3"]);
    assert!(picked.contains("terrain-flyover") && !picked.contains(CASE), "{picked}");
}

#[test]
fn suite_refuses_unknown_cases_and_unreadable_models_in_one_line() {
    let (code, _, stderr) = fails(&["suite", "--cases", "city-strete", "--list"]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("city-strete") && stderr.contains(CASE), "{stderr}");
    let (code, _, stderr) = fails(&["suite", "--cases", "nope"]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("unknown case 'nope'"), "{stderr}");
    let (code, _, stderr) = fails(&[
        "suite",
        "--cases",
        CASE,
        "--size",
        "32x24",
        "--frames",
        "1",
        "--models",
        "/no/such/models/folder",
    ]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("/no/such/models/folder"), "{stderr}");
    let (code, _, _) = fails(&["suite", "--frames", "0", "--list"]);
    assert_eq!(code, Some(2));
    let (code, _, _) = fails(&["suite", "--repeat", "0", "--list"]);
    assert_eq!(code, Some(2));
}

/// `--repeat 2`: each case twice, each run's speedup shown, and every run in the JSON.
#[test]
fn suite_repeats_its_cases() {
    let dir = scratch("suite-repeat");
    let json = dir.join("r.json");
    let stdout = ok(&[
        "--threads",
        "2",
        "suite",
        "--cases",
        CASE,
        "--algos",
        "frustum",
        "--size",
        "48x32",
        "--frames",
        "2",
        "--repeat",
        "2",
        "--json",
        path_arg(&json),
    ]);
    assert!(
        stdout.contains("2 runs of each") && stdout.contains(", 2 runs,"),
        "{stdout}"
    );
    assert!(stdout.contains("interval, runs widened"), "{stdout}");
    let report = read_json(&json);
    let case = &report["cases"][0];
    assert_eq!((case["runs"].as_u64(), case["frames"].as_u64()), (Some(2), Some(2)));
    assert_eq!(case["more_runs"].as_array().map(Vec::len), Some(1));
    let frustum = case["renderers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["name"] == "frustum")
        .unwrap();
    assert_eq!(frustum["frames"], 4);
    assert_eq!(frustum["speedup_runs"].as_array().map(Vec::len), Some(2));
    std::fs::remove_dir_all(&dir).unwrap();
}
