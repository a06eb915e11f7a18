//! DESIGN invariant 2 over every generator: conservative renderers produce frames
//! bit-identical to `zbuffer` (depth bits and item ids, hence colors) from many random views,
//! including views from inside the scene, grazing views, and near/far planes that cut it.

use std::sync::Arc;

use occult_core::{Camera, Scene, Vec3, View};
use occult_raster::{Frame, RasterConfig};
use occult_render::{Algorithm, RenderOptions};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// Small instances of every generator (instancing exercised where the generator has it).
const SCENES: &[&str] = &[
    "terrain:g=48",
    "terrain:g=16,tiles=3",
    "city:blocks=2,detail=2",
    "forest:trees=2,patches=2,levels=1",
    "chessboard:n=40",
    "plant:units=1,floors=2,pipes=6,sides=6",
    "occluder:objects=3",
];

const VIEWS_PER_SCENE: usize = 50;

fn random_view(rng: &mut Pcg64Mcg, scene: &Scene) -> View {
    let b = scene.bounds();
    let diag = b.size().length().max(1e-3);
    loop {
        let pick = |rng: &mut Pcg64Mcg, grow: f32| {
            let c = b.center();
            let h = b.half_extent() * grow + Vec3::splat(diag * 0.01);
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * h
                + c
        };
        let eye = pick(rng, 1.6);
        let target = pick(rng, 0.8);
        let mut cam = Camera::look_at(eye, target);
        cam.fov_y_deg = rng.random_range(15.0..110.0);
        cam.near = diag * 10f32.powf(rng.random_range(-5.0..-1.5));
        cam.far = diag * rng.random_range(0.2..3.0);
        if let Ok(view) = View::new(cam, 96, 64) {
            return view;
        }
    }
}

fn check_identical(algo: Algorithm, threads: usize) {
    let mut rng = Pcg64Mcg::seed_from_u64(2026);
    for spec in SCENES {
        let built = occult_scenes::spec::parse_spec(spec)
            .and_then(|s| s.build())
            .unwrap_or_else(|e| panic!("{spec}: {e}"));
        let scene = Arc::new(built.scene);
        let options = RenderOptions {
            raster: RasterConfig {
                threads,
                ..RasterConfig::default()
            },
        };
        let mut reference = Algorithm::Zbuffer.build(scene.clone(), &options).unwrap();
        let mut renderer = algo.build(scene.clone(), &options).unwrap();
        let (mut a, mut b) = (Frame::new(96, 64).unwrap(), Frame::new(96, 64).unwrap());
        let mut covered_views = 0;
        for i in 0..VIEWS_PER_SCENE {
            let view = random_view(&mut rng, &scene);
            reference.render(&view, &mut a).unwrap();
            renderer.render(&view, &mut b).unwrap();
            assert!(
                a.same_visibility(&b),
                "{} differs from zbuffer on {spec}, view {i}: {:?}",
                algo.name(),
                view.camera()
            );
            covered_views += (a.covered_pixel_count() > 0) as usize;
        }
        // The test must look at something: most random views see part of the scene.
        assert!(
            covered_views >= VIEWS_PER_SCENE / 4,
            "{spec}: only {covered_views} views saw anything"
        );
    }
}

#[test]
fn frustum_is_identical_to_zbuffer_on_every_generator() {
    check_identical(Algorithm::Frustum, 0);
}

#[test]
fn frustum_is_identical_to_zbuffer_single_threaded() {
    check_identical(Algorithm::Frustum, 1);
}

#[test]
fn default_views_and_paths_are_identical() {
    for spec in ["city:blocks=3,detail=2", "terrain:g=64"] {
        let built = occult_scenes::spec::parse_spec(spec).and_then(|s| s.build()).unwrap();
        let cams = occult_scenes::path::parse_path("circle:12", &built.scene, &built.default_camera).unwrap();
        let scene = Arc::new(built.scene);
        let mut z = Algorithm::Zbuffer
            .build(scene.clone(), &RenderOptions::default())
            .unwrap();
        let mut f = Algorithm::Frustum
            .build(scene.clone(), &RenderOptions::default())
            .unwrap();
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
    // zbuffer sends ~2M triangles (sort-last on several threads), frustum far fewer
    // (tile-binned); small frames make tiny on-screen boxes of guard-band-sized triangles.
    let built = occult_scenes::spec::parse_spec("city").and_then(|s| s.build()).unwrap();
    let scene = Arc::new(built.scene);
    let options = RenderOptions {
        raster: RasterConfig {
            threads: 2,
            ..RasterConfig::default()
        },
    };
    let mut z = Algorithm::Zbuffer.build(scene.clone(), &options).unwrap();
    let mut f = Algorithm::Frustum.build(scene.clone(), &options).unwrap();
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
