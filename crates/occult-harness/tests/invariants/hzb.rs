//! DESIGN invariant 2 for `hzb`: frames bit-identical to `zbuffer` over every generator (50
//! random views each for the default, 20 for each other configuration, one renderer object per scene so the visible list carries over between
//! unrelated views) and over whole camera paths (temporal coherence must never leak a stale
//! result), for every configuration that claims to be conservative.

use std::sync::Arc;

use crate::support::{
    assert_identical_on_path, assert_variant_identical_on_every_generator, build_scene, identical_on_every_generator,
    renderer, spec,
};
use occult_core::{Camera, Vec3, View};
use occult_raster::Frame;
use occult_render::{AlgoSpec, RenderError, RenderOptions};

/// Configurations: defaults, each part switched off, extreme octrees and batches.
const CONFIGS: &[&str] = &[
    "hzb",
    "hzb:temporal=off",
    "hzb:pyramid=off,global=off",
    "hzb:global=off",
    "hzb:small=0.25",
    "hzb:small=1,leaf=1,depth=32",
    "hzb:leaf=4,depth=3,batch=1",
    "hzb:recheck=7,area_sort=off,keep_culled=off",
    "hzb:order=count,batch=100000",
    "hzb:occlusion=off",
    "hzb:parallel=structure,workers=3",
    "hzb:parallel=primitive,workers=2",
    "hzb:parallel=hybrid,workers=4,recheck=3",
    "hzb:parallel=structure,workers=3,small=0.25",
    "hzb:parallel=primitive,small=0.25,workers=2",
    "hzb:parallel=hybrid,workers=4,small=0.25",
    "hzb:parallel=columns,workers=2",
    "hzb:parallel=columns,strips=3,refresh=0",
    "hzb:parallel=columns,bands=2",
    "hzb:parallel=columns,workers=3,small=0.25,payoff=off,recheck=2",
    "hzb:small=0.25,temporal=off,refresh=0",
    "hzb:whole=0.01,recheck=2",
    "hzb:retest=off,leaf=64",
    "hzb:refresh=0",
    "hzb:refresh=1,batch=64,leaf=16",
    "hzb:trust=1,recheck=2",
    "hzb:trust=0",
    "hzb:weigh=off,trust=0.9",
    "hzb:parallel=off,recheck=2",
];

identical_on_every_generator! {
    hzb_default_is_identical_on_every_generator: assert_identical_on_every_generator("hzb", 0);
    hzb_single_threaded_is_identical_on_every_generator: assert_identical_on_every_generator("hzb", 1);
}

#[test]
fn hzb_configurations_are_identical_on_every_generator() {
    for c in &CONFIGS[1..] {
        assert_variant_identical_on_every_generator(&spec(c), 0);
    }
}

#[test]
fn hzb_configurations_are_identical_on_paths() {
    for c in CONFIGS {
        let s = spec(c);
        assert_identical_on_path(&s, "city:blocks=3,detail=2", "street:24", 160, 90);
        assert_identical_on_path(&s, "plant:units=1,floors=2,pipes=6,sides=6", "circle:16", 128, 96);
    }
}

#[test]
fn hzb_is_identical_on_paths_of_every_generator() {
    for scene in [
        "terrain:g=48",
        "forest:trees=2,patches=2,levels=1",
        "chessboard:n=40",
        "occluder:objects=3",
        "city:blocks=4,detail=3",
    ] {
        for path in ["circle:20", "flyover:20", "street:20"] {
            assert_identical_on_path(&spec("hzb:recheck=5"), scene, path, 128, 80);
        }
    }
}

#[test]
fn hzb_culls_on_a_city_street_and_keeps_a_visible_list() {
    let built = build_scene("city:blocks=6,detail=2");
    let cams = occult_scenes::path::parse_path("street:6", &built.scene, &built.default_camera).unwrap();
    let scene = Arc::new(built.scene);
    // Without payoff, whose direct frames (timed) would make the counts below depend on the
    // machine.
    let mut h = spec("hzb:payoff=off")
        .build(scene.clone(), &RenderOptions::default())
        .unwrap();
    let mut f = renderer("frustum", &scene);
    let (mut fh, mut ff) = (Frame::new(160, 90).unwrap(), Frame::new(160, 90).unwrap());
    let (mut th, mut tf) = (0, 0);
    let (mut tests, mut samples, mut drawn) = (0, 0, 0);
    for (i, cam) in cams.iter().enumerate() {
        let view = View::new(*cam, 160, 90).unwrap();
        let sh = h.render(&view, &mut fh).unwrap();
        let sf = f.render(&view, &mut ff).unwrap();
        assert!(fh.same_visibility(&ff));
        th += sh.triangles_submitted;
        tf += sf.triangles_submitted;
        tests += sh.counters.get("occlusion_tests");
        samples += sh.counters.get("pyramid_tests");
        assert!(sh.counters.get("visible_list") > 0);
        if i > 0 {
            drawn += sh.counters.get("visible_list_drawn");
        }
    }
    assert!(tests > 0 && samples > 0 && drawn > 0);
    assert!(th < tf, "hzb submitted {th} triangles, frustum {tf}");
}

#[test]
fn hzb_skips_an_imprecise_visible_list_and_keeps_a_precise_one() {
    // An orbit in 6 steps (60 degrees a frame): most of last frame's list is hidden now, so the
    // list is measured imprecise and skipped, and the frames submit less than drawing it would;
    // a street walk keeps its list. Frames stay exact either way. (`weigh` off: the precision
    // alone decides.)
    let built = build_scene("city:blocks=3,detail=2");
    let scene = Arc::new(built.scene);
    let run = |algo: &str, path: &str| {
        let cams = occult_scenes::path::parse_path(path, &scene, &built.default_camera).expect("a generated path");
        let mut h = spec(algo)
            .build(scene.clone(), &RenderOptions::default())
            .expect("hzb builds");
        let mut z = renderer("zbuffer", &scene);
        let (mut fh, mut fz) = (
            Frame::new(160, 90).expect("a frame"),
            Frame::new(160, 90).expect("a frame"),
        );
        let (mut skipped, mut submitted, mut precision) = (0, 0, Vec::new());
        for cam in &cams {
            let view = View::new(*cam, 160, 90).expect("a view");
            let s = h.render(&view, &mut fh).expect("hzb renders");
            z.render(&view, &mut fz).expect("zbuffer renders");
            assert!(fh.same_visibility(&fz), "{algo} on {path}");
            skipped += s.counters.get("visible_list_skipped");
            submitted += s.triangles_submitted;
            precision.push(s.counters.get("visible_list_precision_pct"));
        }
        (skipped, submitted, precision)
    };
    let (skipped, submitted, precision) = run("hzb:payoff=off,trust=0.9,weigh=off", "circle:6");
    let (never, blind, _) = run("hzb:payoff=off,trust=0,weigh=off", "circle:6");
    assert!(
        skipped > 0,
        "the orbit's list was never skipped (precision {precision:?})"
    );
    assert_eq!(never, 0, "trust=0 without weigh never skips");
    assert!(
        submitted < blind,
        "skipping submitted {submitted} triangles, drawing the list {blind}"
    );
    let (skipped, _, precision) = run("hzb:payoff=off,trust=0.5,weigh=off", "street:12");
    assert_eq!(skipped, 0, "a street walk's list is precise (precision {precision:?})");
}

#[test]
fn hzb_draws_mostly_visible_instances_whole() {
    // A city overview: most of each building is visible, so with a low `whole` fraction the
    // visible list draws instances whole (and the traversal skips them); frames stay exact.
    let built = build_scene("city:blocks=3,detail=2");
    let cams = occult_scenes::path::parse_path("circle:4", &built.scene, &built.default_camera).unwrap();
    let scene = Arc::new(built.scene);
    for (whole, expect) in [("0.05", true), ("0", false)] {
        let mut h = spec(&format!("hzb:whole={whole},payoff=off"))
            .build(scene.clone(), &RenderOptions::default())
            .unwrap();
        let mut z = renderer("zbuffer", &scene);
        let (mut fh, mut fz) = (Frame::new(160, 90).unwrap(), Frame::new(160, 90).unwrap());
        let mut drawn_whole = 0;
        for cam in &cams {
            let view = View::new(*cam, 160, 90).unwrap();
            drawn_whole += h.render(&view, &mut fh).unwrap().counters.get("whole_drawn");
            z.render(&view, &mut fz).unwrap();
            assert!(fh.same_visibility(&fz), "whole={whole}");
        }
        assert_eq!(
            drawn_whole > 0,
            expect,
            "whole={whole}: {drawn_whole} instances drawn whole"
        );
    }
}

#[test]
fn hzb_bad_parameters_are_errors() {
    let scene = Arc::new(build_scene("chessboard:n=4").scene);
    for bad in [
        "hzb:leaf=0",
        "hzb:depth=0",
        "hzb:recheck=-3",
        "hzb:recheck=0",
        "hzb:small=2",
        "hzb:batch=0",
        "hzb:order=x",
        "hzb:whole=2",
        "hzb:trust=1.5",
        "hzb:refresh=-1",
        "hzb:parallel=columns,strips=0",
        "hzb:strips=17",
        "hzb:parallel=rows",
    ] {
        let s = spec(bad);
        match s.build(scene.clone(), &RenderOptions::default()) {
            Err(RenderError::BadParameter(m)) => assert!(m.contains("hzb"), "{bad}: {m}"),
            Err(e) => panic!("{bad}: wrong error {e}"),
            Ok(_) => panic!("{bad}: accepted"),
        }
    }
    assert!(AlgoSpec::parse("hzb:leef=3").is_err());
}

#[test]
fn hzb_distributions_report_worker_idle_time() {
    let built = build_scene("city:blocks=3,detail=2");
    let scene = Arc::new(built.scene);
    for d in ["structure", "primitive", "hybrid", "columns"] {
        let s = spec(&format!("hzb:parallel={d},workers=3"));
        let mut h = s.build(scene.clone(), &RenderOptions::default()).unwrap();
        let view = View::new(built.default_camera, 96, 64).unwrap();
        let stats = h.render(&view, &mut Frame::new(96, 64).unwrap()).unwrap();
        let idle: Vec<u64> = (0..3)
            .map(|k| stats.counters.get(&format!("worker{k}_idle_us")))
            .collect();
        assert!(idle.contains(&0), "{d}: the slowest worker waits for nobody: {idle:?}");
        assert!(stats.counters.0.iter().any(|(k, _)| *k == "worker2_busy_us"));
        assert!(stats.triangles_submitted > 0);
    }
}

#[test]
fn hzb_frame_size_changes_and_mismatches() {
    let scene = Arc::new(build_scene("occluder:objects=3").scene);
    let mut h = renderer("hzb", &scene);
    let mut z = renderer("zbuffer", &scene);
    let mut c = renderer("hzb:parallel=columns,workers=3", &scene);
    let cam = Camera::look_at(Vec3::new(0.0, 3.0, 30.0), Vec3::ZERO);
    for (w, hh) in [(64, 48), (7, 3), (1, 1), (96, 64)] {
        let view = View::new(cam, w, hh).unwrap();
        let (mut a, mut b) = (Frame::new(w, hh).unwrap(), Frame::new(w, hh).unwrap());
        h.render(&view, &mut a).unwrap();
        z.render(&view, &mut b).unwrap();
        assert!(a.same_visibility(&b), "{w}x{hh}");
        let mut d = Frame::new(w, hh).unwrap();
        c.render(&view, &mut d).unwrap();
        assert!(d.same_visibility(&b), "columns, {w}x{hh}");
    }
    let view = View::new(cam, 64, 48).unwrap();
    assert!(h.render(&view, &mut Frame::new(32, 32).unwrap()).is_err());
}
