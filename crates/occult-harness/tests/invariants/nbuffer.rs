//! `nbuffer` (Décoret 2005 §3.1): frames bit-identical to `zbuffer` (DESIGN invariant 2) over
//! every generator with random views and over whole camera paths, in every configuration;
//! bad parameters are errors; the counters add up and the culling culls.

use std::sync::Arc;

use crate::support::{
    assert_identical_on_every_generator, assert_identical_on_path, assert_variant_identical_on_every_generator,
    build_scene, renderer,
};
use occult_core::View;
use occult_raster::Frame;
use occult_render::{AlgoSpec, RenderError, RenderOptions};

const CONFIGS: &[&str] = &[
    "nbuffer",
    "nbuffer:hierarchy=flat",
    "nbuffer:cover=one",
    "nbuffer:hierarchy=flat,cover=one",
    "nbuffer:leaf=7,group_leaf=1",
    "nbuffer:test=query",
    "nbuffer:test=query,hierarchy=flat",
    "nbuffer:occluders=visible,leaf=4096,scale=1,passes=1,payoff=off",
    "nbuffer:occluders=both,near_area=0,near_max=3",
    "nbuffer:scale=1,passes=1",
    "nbuffer:scale=8,hierarchy=flat,cover=one",
    "nbuffer:scale=4,payoff=off,leaf=7,group_leaf=1",
];

#[test]
fn every_configuration_is_identical_to_zbuffer_on_every_generator() {
    assert_identical_on_every_generator(&AlgoSpec::parse(CONFIGS[0]).unwrap(), 0);
    for spec in &CONFIGS[1..] {
        assert_variant_identical_on_every_generator(&AlgoSpec::parse(spec).unwrap(), 0);
    }
}

#[test]
fn single_threaded_is_identical_to_zbuffer() {
    assert_identical_on_every_generator(&AlgoSpec::parse("nbuffer").unwrap(), 1);
}

#[test]
fn paths_are_identical_to_zbuffer() {
    for spec in CONFIGS {
        let spec = AlgoSpec::parse(spec).unwrap();
        assert_identical_on_path(&spec, "city:blocks=3,detail=2", "street:12", 160, 90);
        assert_identical_on_path(&spec, "terrain:g=64,tiles=2", "flyover:8", 128, 96);
        assert_identical_on_path(&spec, "forest:trees=3,patches=2,levels=1", "circle:8", 120, 80);
        assert_identical_on_path(&spec, "occluder:objects=4", "circle:8", 101, 77);
    }
}

#[test]
fn bad_parameters_are_errors() {
    let built = build_scene("city:blocks=1,detail=1");
    let scene = Arc::new(built.scene);
    for bad in [
        "nbuffer:scale=3",
        "nbuffer:passes=0",
        "nbuffer:near_area=2",
        "nbuffer:occluders=all",
        "nbuffer:payoff=sometimes",
        "nbuffer:leaf=0",
        "nbuffer:group_leaf=0",
        "nbuffer:hierarchy=octree",
        "nbuffer:cover=two",
        "nbuffer:test=hardware",
        "nbuffer:leaf=-3",
        "nbuffer:leaf=many",
    ] {
        let spec = AlgoSpec::parse(bad).unwrap();
        match spec.build(scene.clone(), &RenderOptions::default()) {
            Err(RenderError::BadParameter(msg)) => assert!(msg.contains("nbuffer"), "{bad}: {msg}"),
            Err(e) => panic!("{bad}: not a bad-parameter error: {e}"),
            Ok(_) => panic!("{bad} was accepted"),
        }
    }
    assert!(AlgoSpec::parse("nbuffer:levels=3")
        .and_then(|s| s.build(scene.clone(), &RenderOptions::default()).map(|_| ()))
        .is_err());
}

/// A small city and a street walk through it.
fn city_street() -> (Arc<occult_core::Scene>, Vec<occult_core::Camera>) {
    let built = build_scene("city:blocks=4,detail=2");
    let cams = occult_scenes::path::parse_path("street:10", &built.scene, &built.default_camera).unwrap();
    (Arc::new(built.scene), cams)
}

#[test]
fn street_walk_culls_with_at_most_four_lookups_per_rectangle() {
    let (scene, cams) = city_street();
    for spec in [
        "nbuffer",
        "nbuffer:hierarchy=flat",
        "nbuffer:occluders=visible,payoff=off",
    ] {
        let mut r = AlgoSpec::parse(spec)
            .unwrap()
            .build(scene.clone(), &RenderOptions::default())
            .unwrap();
        let mut frame = Frame::new(160, 90).unwrap();
        let (mut culled, mut occluders) = (0, 0);
        for (i, cam) in cams.iter().enumerate() {
            let view = View::new(*cam, 160, 90).unwrap();
            let s = r.render(&view, &mut frame).unwrap();
            let lookups = s.counters.get("nbuffer_lookups");
            assert!(
                lookups <= 4 * s.rects_tested,
                "{spec} frame {i}: {lookups} lookups for {} rects",
                s.rects_tested
            );
            assert!(s.rects_culled <= s.rects_tested);
            if i == 0 && spec.contains("occluders=visible") {
                assert_eq!(s.counters.get("occluders_drawn"), 0, "no occluders on the first frame");
            }
            culled += s.rects_culled;
            occluders += s.counters.get("occluders_drawn");
        }
        assert!(culled > 0, "{spec}: nothing culled along a street");
        assert!(occluders > 0, "{spec}: no occluders after the first frame");
    }
}

/// Table 2: occlusion queries test the same objects as the N-buffer (the occluders are the
/// same: the same near objects, and the same exact visible set, the frames being identical) and cull at least what it culls (the
/// N-buffer's rectangle and rounded keys are conservative bounds of the query's silhouette),
/// at the cost of one depth comparison per silhouette pixel instead of at most four lookups.
#[test]
fn occlusion_queries_test_the_same_objects_and_cull_at_least_as_much() {
    let (scene, cams) = city_street();
    let build = |spec: &str| {
        AlgoSpec::parse(spec)
            .unwrap()
            .build(scene.clone(), &RenderOptions::default())
            .unwrap()
    };
    let (mut nb, mut oq) = (
        build("nbuffer:hierarchy=flat,payoff=off,passes=1"),
        build("nbuffer:hierarchy=flat,test=query,payoff=off,passes=1"),
    );
    let (mut a, mut b) = (Frame::new(160, 90).unwrap(), Frame::new(160, 90).unwrap());
    let (mut comparisons, mut lookups) = (0, 0);
    for (i, cam) in cams.iter().enumerate() {
        let view = View::new(*cam, 160, 90).unwrap();
        let s = nb.render(&view, &mut a).unwrap();
        let q = oq.render(&view, &mut b).unwrap();
        assert!(a.same_visibility(&b), "frame {i}");
        assert_eq!(s.rects_tested, q.rects_tested, "frame {i}: not the same objects tested");
        assert!(q.rects_culled >= s.rects_culled, "frame {i}: the query culled less");
        assert_eq!(
            s.counters.get("rect_pixels"),
            q.counters.get("rect_pixels"),
            "frame {i}"
        );
        assert!(
            q.counters.get("depth_comparisons") <= q.counters.get("rect_pixels"),
            "frame {i}"
        );
        assert_eq!(s.counters.get("depth_comparisons"), s.counters.get("nbuffer_lookups"));
        assert_eq!(q.counters.get("nbuffer_lookups"), 0);
        comparisons += q.counters.get("depth_comparisons");
        lookups += s.counters.get("nbuffer_lookups");
    }
    assert!(
        comparisons > 10 * lookups,
        "{comparisons} query comparisons, {lookups} lookups"
    );
}

#[test]
fn resolution_change_and_frame_mismatch() {
    let built = build_scene("city:blocks=2,detail=1");
    let scene = Arc::new(built.scene);
    let mut r = renderer("nbuffer", &scene);
    let mut z = renderer("zbuffer", &scene);
    for (w, h) in [(64, 48), (33, 97), (64, 48)] {
        let view = View::new(built.default_camera, w, h).unwrap();
        let (mut a, mut b) = (Frame::new(w, h).unwrap(), Frame::new(w, h).unwrap());
        z.render(&view, &mut a).unwrap();
        r.render(&view, &mut b).unwrap();
        assert!(a.same_visibility(&b), "{w}x{h}");
    }
    let view = View::new(built.default_camera, 64, 48).unwrap();
    let mut wrong = Frame::new(48, 64).unwrap();
    assert!(matches!(
        r.render(&view, &mut wrong),
        Err(RenderError::FrameSizeMismatch { .. })
    ));
}

/// §3.2: sprites culled with the N-buffer give the same frame as sprites all drawn.
#[test]
fn particle_frames_are_identical_with_and_without_culling() {
    use occult_raster::{Extremum, NBuffer, RasterConfig, Rasterizer};
    use occult_render::nbuffer::particles::{draw_particles, Particles};
    for (scene_spec, path) in [
        ("city:blocks=2,detail=2", "street:4"),
        ("forest:trees=3,patches=2,levels=1", "circle:4"),
    ] {
        let built = build_scene(scene_spec);
        let cams = occult_scenes::path::parse_path(path, &built.scene, &built.default_camera).unwrap();
        let scene = Arc::new(built.scene);
        let mut z = renderer("zbuffer", &scene);
        let mut raster = Rasterizer::new(RasterConfig::default()).unwrap();
        let (w, h) = (160, 120);
        let (mut culled_total, mut single) = (0, 0);
        for (pow2, seed) in [(false, 1), (true, 2)] {
            let particles = Particles::scatter(&scene.bounds(), 20_000, 64, pow2, 0.5, seed).unwrap();
            for cam in &cams {
                let view = View::new(*cam, w, h).unwrap();
                let (mut a, mut b) = (Frame::new(w, h).unwrap(), Frame::new(w, h).unwrap());
                z.render(&view, &mut a).unwrap();
                z.render(&view, &mut b).unwrap();
                let nb = NBuffer::with_levels(Extremum::Min, b.depth(), w, h, particles.levels_needed()).unwrap();
                let first = scene.item_count();
                let mut c = b.clone();
                let all = draw_particles(&mut raster, &view, &mut a, &particles, first, None, true).unwrap();
                let cut = draw_particles(&mut raster, &view, &mut b, &particles, first, Some(&nb), true).unwrap();
                let one = draw_particles(&mut raster, &view, &mut c, &particles, first, Some(&nb), false).unwrap();
                assert!(a.same_visibility(&b), "{scene_spec}: culled sprites changed the frame");
                assert!(b.same_visibility(&c), "{scene_spec}: batched and single tests differ");
                assert_eq!(
                    (cut.sprites_culled, cut.lookups, cut.single_lookup_tests, cut.raster),
                    (one.sprites_culled, one.lookups, one.single_lookup_tests, one.raster),
                    "{scene_spec}: batched and single tests differ"
                );
                assert_eq!(all.sprites_culled, 0);
                assert_eq!(all.sprites_in_view, cut.sprites_in_view);
                assert!(cut.lookups <= 4 * cut.sprites_in_view);
                culled_total += cut.sprites_culled;
                single += cut.single_lookup_tests;
                // Only power-of-two sprites take the single lookup.
                assert!(cut.single_lookup_tests <= cut.sprites_in_view);
            }
        }
        assert!(culled_total > 0, "{scene_spec}: no sprite culled");
        assert!(single > 0, "{scene_spec}: no single-lookup test");
    }
}

#[test]
fn bad_particle_parameters_are_errors() {
    use occult_core::{Aabb, Vec3};
    use occult_render::nbuffer::particles::Particles;
    let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
    assert!(Particles::scatter(&b, 10, 0, false, 0.5, 1).is_err());
    assert!(Particles::scatter(&b, 10, 65, false, 0.5, 1).is_err());
    assert!(Particles::scatter(&b, 10, 8, false, 0.0, 1).is_err());
    assert!(Particles::scatter(&b, 10, 8, false, f32::NAN, 1).is_err());
    assert!(Particles::scatter(&b, usize::MAX, 8, false, 0.5, 1).is_err());
    assert!(Particles::scatter(&Aabb::EMPTY, 10, 8, false, 0.5, 1).is_err());
    let p = Particles::scatter(&b, 1000, 64, true, 0.5, 1).unwrap();
    assert!(p.sizes.iter().all(|s| s.is_power_of_two() && *s <= 64));
    assert_eq!(p.levels_needed(), 7);
}
