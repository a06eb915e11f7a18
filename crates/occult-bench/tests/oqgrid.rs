//! oqgrid: frames bit-identical to zbuffer (tmp local harness).

use std::sync::Arc;

use occult_core::{Camera, Scene, Vec3, View};
use occult_raster::Frame;
use occult_render::oqgrid::{GridKind, OqGrid, OqGridOptions, Resolution};
use occult_render::{Algorithm, RenderOptions, Renderer};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

const SCENES: &[&str] = &[
    "terrain:g=48",
    "terrain:g=16,tiles=3",
    "city:blocks=2,detail=2",
    "forest:trees=2,patches=2,levels=1",
    "chessboard:n=40",
    "plant:units=1,floors=2,pipes=6,sides=6",
    "occluder:objects=3",
];

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

fn check(o: OqGridOptions) {
    let mut rng = Pcg64Mcg::seed_from_u64(2026);
    for spec in SCENES {
        let built = occult_scenes::spec::parse_spec(spec).and_then(|s| s.build()).unwrap();
        let scene = Arc::new(built.scene);
        let options = RenderOptions::default();
        let mut reference = Algorithm::Zbuffer.build(scene.clone(), &options).unwrap();
        let mut r = OqGrid::with_options(scene.clone(), &options, &o).unwrap();
        let (mut a, mut b) = (Frame::new(96, 64).unwrap(), Frame::new(96, 64).unwrap());
        let mut hidden = 0;
        for i in 0..50 {
            let view = random_view(&mut rng, &scene);
            reference.render(&view, &mut a).unwrap();
            r.render(&view, &mut b).unwrap();
            hidden += r.last_counts().queries_hidden;
            assert!(
                a.same_visibility(&b),
                "{o:?} differs on {spec} view {i}: {:?}",
                view.camera()
            );
        }
        eprintln!("{spec}: hidden {hidden}");
    }
}

#[test]
fn nested_default() {
    check(OqGridOptions::default());
}
#[test]
fn uniform_b1() {
    check(OqGridOptions {
        grid: GridKind::Uniform,
        batch: 1,
        resolution: Resolution::Cells(16),
        ..Default::default()
    });
}
