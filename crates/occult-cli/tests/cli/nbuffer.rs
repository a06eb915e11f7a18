//! End-to-end tests of `occult particles` and `occult shadows` (Décoret 2005 §3.2, §3.3): small
//! scenes and frames; bad arguments end in one line on stderr and a non-zero status.

use super::*;

#[test]
fn particles_cull_and_report() {
    let [png, j] = scratch_files("particles", ["p.png", "p.json"]);
    let (png, j) = (png.as_str(), j.as_str());
    let out = ok(&[
        "particles",
        "--scene",
        CITY,
        "--count",
        "20000",
        "--sizes",
        "pow2",
        "--size",
        "96x64",
        "--out",
        png,
        "--json",
        j,
    ]);
    assert!(out.contains("sprites culled"), "{out}");
    let v = read_json(std::path::Path::new(j));
    assert_eq!(v["cull"], true);
    assert!(v["sprites_culled"].as_u64().unwrap() > 0);
    assert!(v["lookups"].as_u64().unwrap() <= 4 * v["sprites_in_view"].as_u64().unwrap());
    ok(&[
        "particles",
        "--scene",
        CITY,
        "--count",
        "2000",
        "--cull",
        "off",
        "--size",
        "64x48",
        "--out",
        png,
        "--json",
        j,
    ]);
    assert_eq!(read_json(std::path::Path::new(j))["sprites_culled"], 0);
    assert_eq!(image::open(png).unwrap().width(), 64);
}

#[test]
fn shadows_are_identical_with_and_without_clamping() {
    let [png, j] = scratch_files("shadows", ["s.png", "s.json"]);
    let (png, j) = (png.as_str(), j.as_str());
    let out = ok(&[
        "shadows", "--scene", CITY, "--size", "96x64", "--litmap", "64", "--out", png, "--json", j,
    ]);
    assert!(out.contains("shadows identical: yes"), "{out}");
    let v = read_json(std::path::Path::new(j));
    assert_eq!(v["differing_pixels"], 0);
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(runs[0]["shadowed_pixels"], runs[1]["shadowed_pixels"]);
    assert!(runs[1]["stencil_fragments"].as_f64().unwrap() <= runs[0]["stencil_fragments"].as_f64().unwrap());
    // Along a path: per-frame figures, identical shadows on every frame, the means in `runs`.
    let out = ok(&[
        "shadows", "--scene", CITY, "--path", "circle:3", "--size", "96x64", "--litmap", "64", "--out", png, "--json",
        j,
    ]);
    assert!(out.contains("shadows identical on every frame: yes"), "{out}");
    assert_eq!(out.matches("frame ").count(), 3 + 1, "{out}"); // 3 frames and the "frames" line
    let v = read_json(std::path::Path::new(j));
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 3);
    assert_eq!(v["differing_pixels"], 0);
    let mean_on: f64 = frames
        .iter()
        .map(|f| f["runs"][1]["stencil_fragments"].as_f64().unwrap())
        .sum::<f64>()
        / 3.0;
    assert!((v["runs"][1]["stencil_fragments"].as_f64().unwrap() - mean_on).abs() < 1e-6);
    for f in frames {
        assert_eq!(f["differing_pixels"], 0);
        assert_eq!(f["runs"][0]["shadowed_pixels"], f["runs"][1]["shadowed_pixels"]);
    }
    ok(&[
        "shadows",
        "--scene",
        "terrain:g=24",
        "--clamp",
        "on",
        "--size",
        "64x48",
        "--out",
        png,
    ]);
    assert_eq!(image::open(png).unwrap().height(), 48);
}

#[test]
fn bad_arguments_are_one_line_errors() {
    let [png] = scratch_files("nbuffer-bad", ["x.png"]);
    let png = png.as_str();
    for args in [
        vec!["particles", "--scene", CITY, "--sizes", "1-65", "--out", png],
        vec!["particles", "--scene", CITY, "--sizes", "pow3", "--out", png],
        vec!["particles", "--scene", CITY, "--cull", "maybe", "--out", png],
        vec!["particles", "--scene", CITY, "--count", "999999999999", "--out", png],
        vec!["particles", "--scene", CITY, "--fill", "0", "--out", png],
        vec!["shadows", "--scene", CITY, "--clamp", "sometimes", "--out", png],
        vec!["shadows", "--scene", CITY, "--cone", "0", "--out", png],
        vec!["shadows", "--scene", CITY, "--litmap", "0", "--out", png],
        vec!["shadows", "--scene", CITY, "--leaf", "0", "--out", png],
        vec!["shadows", "--scene", CITY, "--path", "nowhere:3", "--out", png],
        vec![
            "shadows",
            "--scene",
            CITY,
            "--path",
            "circle:3",
            "--view",
            "circle:3:1",
            "--out",
            png,
        ],
        vec!["shadows", "--scene", CITY, "--light", "1,2", "--out", png],
        vec!["shadows", "--scene", "nowhere:x=1", "--out", png],
    ] {
        fails(&args);
    }
}
