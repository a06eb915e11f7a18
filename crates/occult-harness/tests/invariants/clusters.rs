//! `clusters`: frames bit-identical to `zbuffer` in every configuration (temporal first pass,
//! growing batches, the payoff's direct frames), on every generator and along paths, and its
//! counters.

use std::sync::Arc;

use crate::support::{
    assert_identical_on_every_generator, assert_identical_on_path, assert_variant_identical_on_every_generator,
    build_scene, renderer,
};
use occult_core::View;
use occult_raster::Frame;
use occult_render::AlgoSpec;

#[test]
fn clusters_are_identical_to_zbuffer_on_every_generator() {
    assert_identical_on_every_generator(&AlgoSpec::parse("clusters").unwrap(), 0);
}

#[test]
fn clusters_are_identical_single_threaded() {
    assert_identical_on_every_generator(&AlgoSpec::parse("clusters").unwrap(), 1);
}

#[test]
fn every_configuration_is_identical() {
    for spec in [
        "clusters:payoff=off",
        "clusters:payoff=off,temporal=off",
        "clusters:payoff=off,behind=off",
        "clusters:payoff=off,groups=off",
        "clusters:payoff=off,weigh=off,trust=0",
        "clusters:payoff=off,size=8,batch=1",
        "clusters:payoff=off,size=512,batch=1000000",
    ] {
        let spec = AlgoSpec::parse(spec).unwrap();
        assert_variant_identical_on_every_generator(&spec, 0);
    }
}

#[test]
fn identical_along_paths_with_coherent_and_jumping_views() {
    let spec = AlgoSpec::parse("clusters:payoff=off").unwrap();
    assert_identical_on_path(&spec, "city:blocks=3,detail=2", "street:10", 160, 90);
    assert_identical_on_path(&spec, "plant:units=1", "circle:12", 160, 90);
    assert_identical_on_path(&spec, "forest:trees=2,patches=2,levels=1", "flyover:8", 160, 90);
}

#[test]
fn a_street_culls_clusters_and_reuses_last_frames() {
    // Along a street most of the city is hidden: whole instances and clusters of visible
    // ones are culled, and from the second frame on last frame's clusters are drawn first.
    let built = build_scene("city:blocks=3,detail=2");
    let cams = occult_scenes::path::parse_path("street:6", &built.scene, &built.default_camera).unwrap();
    let scene = Arc::new(built.scene);
    let mut r = renderer("clusters:payoff=off", &scene);
    let mut frame = Frame::new(320, 180).unwrap();
    let (mut firsts, mut culled, mut removed, mut tested) = (0, 0, 0, 0);
    for (i, cam) in cams.iter().enumerate() {
        let s = r.render(&View::new(*cam, 320, 180).unwrap(), &mut frame).unwrap();
        tested += s.counters.get("clusters_tested");
        culled += s.counters.get("clusters_culled") + s.counters.get("instances_culled");
        removed += s.counters.get("removed_triangles");
        assert!(s.triangles_submitted < scene.item_count(), "frame {i}");
        if i == 0 {
            assert_eq!(
                s.counters.get("first_triangles"),
                0,
                "a first frame has no last frame to draw first"
            );
        }
        firsts += u64::from(s.counters.get("first_triangles") > 0);
    }
    assert!(
        tested > 0 && culled > 0 && removed > 0,
        "tested {tested}, culled {culled}, removed {removed}"
    );
    assert!(firsts > 0, "no frame drew last frame's clusters first");
}

#[test]
fn clusters_behind_their_instance_wait_for_its_front() {
    // A building's front hides its back, but a window's tests run before any of it is drawn:
    // with `behind` the clusters behind each instance's centre are asked again after the
    // front, and fewer triangles are drawn for the same frames.
    for (spec, path) in [("city:blocks=3,detail=2", "circle:4"), ("plant:units=1", "circle:4")] {
        let built = build_scene(spec);
        let cams = occult_scenes::path::parse_path(path, &built.scene, &built.default_camera).unwrap();
        let scene = Arc::new(built.scene);
        let mut on = renderer("clusters:payoff=off,temporal=off", &scene);
        let mut off = renderer("clusters:payoff=off,temporal=off,behind=off", &scene);
        let (mut a, mut b) = (Frame::new(320, 180).unwrap(), Frame::new(320, 180).unwrap());
        let (mut drawn_on, mut drawn_off, mut waited) = (0, 0, 0);
        for (i, cam) in cams.iter().enumerate() {
            let view = View::new(*cam, 320, 180).unwrap();
            let s = on.render(&view, &mut a).unwrap();
            drawn_on += s.triangles_submitted;
            waited += s.counters.get("clusters_deferred");
            drawn_off += off.render(&view, &mut b).unwrap().triangles_submitted;
            assert!(
                a.depth() == b.depth() && a.items() == b.items(),
                "{spec} frame {i}: behind on and off differ"
            );
        }
        assert!(waited > 0, "{spec}: no cluster waited for its instance's front");
        assert!(
            drawn_on < drawn_off,
            "{spec}: behind on drew {drawn_on} triangles, off {drawn_off}"
        );
    }
}
