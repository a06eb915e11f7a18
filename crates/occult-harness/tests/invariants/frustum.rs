//! DESIGN invariant 2 over every generator: conservative renderers produce frames
//! bit-identical to `zbuffer` (depth bits and item ids, hence colors) from many random views,
//! including views from inside the scene, grazing views, and near/far planes that cut it.

use std::sync::Arc;

use crate::support::{
    assert_identical_on_every_generator, assert_identical_on_path, assert_variant_identical_on_every_generator,
    build_scene, renderer,
};
use occult_core::View;
use occult_raster::{Frame, RasterConfig, Strategy};
use occult_render::{AlgoSpec, Algorithm, RenderOptions};

#[test]
fn frustum_is_identical_to_zbuffer_on_every_generator() {
    assert_identical_on_every_generator(&Algorithm::FRUSTUM.into(), 0);
}

#[test]
fn frustum_is_identical_to_zbuffer_single_threaded() {
    assert_identical_on_every_generator(&Algorithm::FRUSTUM.into(), 1);
}

#[test]
fn frustum_with_other_leaf_sizes_is_identical() {
    let spec = AlgoSpec::parse("frustum:leaf=7,group_leaf=1").unwrap();
    assert_variant_identical_on_every_generator(&spec, 0);
    assert_identical_on_path(&spec, "city:blocks=3,detail=2", "street:10", 160, 90);
}

/// Leaves drawn as index lists (`clusters=off`) and as clusters (the default) draw the same
/// frames; the clusters' memory is counted.
#[test]
fn frustum_with_index_lists_is_identical() {
    let spec = AlgoSpec::parse("frustum:clusters=off").unwrap();
    assert_variant_identical_on_every_generator(&spec, 0);
    let scene = Arc::new(build_scene("terrain:g=64").scene);
    let lists = spec.build(scene.clone(), &RenderOptions::default()).unwrap();
    let clusters = renderer("frustum", &scene);
    assert!(clusters.memory_bytes() > lists.memory_bytes());
}

#[test]
fn default_views_and_paths_are_identical() {
    for spec in ["city:blocks=3,detail=2", "terrain:g=64"] {
        let built = build_scene(spec);
        let cams = occult_scenes::path::parse_path("circle:12", &built.scene, &built.default_camera).unwrap();
        let scene = Arc::new(built.scene);
        let mut z = renderer("zbuffer", &scene);
        let mut f = renderer("frustum", &scene);
        let (mut a, mut b) = (Frame::new(160, 90).unwrap(), Frame::new(160, 90).unwrap());
        for cam in cams.iter().chain([&built.default_camera]) {
            let view = View::new(*cam, 160, 90).unwrap();
            let sa = z.render(&view, &mut a).unwrap();
            let sb = f.render(&view, &mut b).unwrap();
            assert!(a.same_visibility(&b), "{spec}: {cam:?}");
            assert!(a.covered_pixel_count() > 0, "{spec}: path view sees nothing: {cam:?}");
            assert!(sb.triangles_submitted <= sa.triangles_submitted);
        }
    }
}

#[test]
fn identical_when_zbuffer_and_frustum_take_different_raster_strategies() {
    // zbuffer sends ~2M triangles (sort-last on several threads), frustum far fewer, here
    // tile-binned (the automatic strategy would draw them directly); small frames make tiny
    // on-screen boxes of guard-band-sized triangles.
    let built = build_scene("city");
    let scene = Arc::new(built.scene);
    let options = RenderOptions {
        raster: RasterConfig {
            threads: 2,
            ..RasterConfig::default()
        },
        ..RenderOptions::default()
    };
    let binned = RenderOptions {
        raster: RasterConfig {
            strategy: Strategy::Binned,
            ..options.raster.clone()
        },
        ..RenderOptions::default()
    };
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &options).unwrap();
    let mut f = Algorithm::FRUSTUM.build(scene.clone(), &binned).unwrap();
    let cams = occult_scenes::path::parse_path("street:6", &scene, &built.default_camera).unwrap();
    for (w, h) in [(64, 48), (160, 90)] {
        let (mut a, mut b) = (Frame::new(w, h).unwrap(), Frame::new(w, h).unwrap());
        for cam in &cams {
            let view = View::new(*cam, w, h).unwrap();
            let sa = z.render(&view, &mut a).unwrap();
            let sb = f.render(&view, &mut b).unwrap();
            assert!(sa.triangles_submitted >= 200_000 && sb.triangles_submitted < sa.triangles_submitted);
            assert!(a.same_visibility(&b), "{w}x{h}: {cam:?}");
        }
    }
}
