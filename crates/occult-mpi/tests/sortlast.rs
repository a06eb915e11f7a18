//! Sort-last over thread ranks: frames bit-identical to the single-process `zbuffer` on every
//! generator at 1, 2, 3 and 4 ranks, for brute force and culling renderers; failures end every
//! rank with one error.

use std::sync::Arc;

use occult_core::{Camera, Scene, Vec3, View};
use occult_mpi::{run_threads, sort_last_options, SortLastConfig};
use occult_raster::{Frame, RasterConfig};
use occult_render::{AlgoSpec, Algorithm, RenderError, RenderOptions};

/// Small instances of every generator (as occult-harness's invariant tests take them).
const SCENES: &[&str] = &[
    "terrain:g=48",
    "terrain:g=16,tiles=3",
    "city:blocks=2,detail=2",
    "forest:trees=2,patches=2,levels=1",
    "chessboard:n=40",
    "plant:units=1,floors=2,pipes=6,sides=6",
    "occluder:objects=3",
];

fn one_thread() -> RenderOptions {
    RenderOptions {
        raster: RasterConfig {
            threads: 1,
            ..RasterConfig::default()
        },
        ..RenderOptions::default()
    }
}

/// The generator's default view and views from the eight corners of the bounds, looking at
/// the centre.
fn views(scene: &Scene, default: Camera) -> Vec<View> {
    let b = scene.bounds();
    let mut out = vec![View::new(default, 96, 64).expect("the generator's view is valid")];
    for corner in b.corners() {
        let eye = b.center() + (corner - b.center()) * 1.3 + Vec3::splat(1e-3);
        let mut cam = Camera::look_at(eye, b.center());
        cam.near = b.size().length() * 1e-4;
        cam.far = b.size().length() * 4.0;
        if let Ok(v) = View::new(cam, 96, 64) {
            out.push(v);
        }
    }
    out
}

fn check(algo: &str) {
    check_with(algo, SortLastConfig::default());
}

fn check_with(algo: &str, config: SortLastConfig) {
    let spec = AlgoSpec::parse(algo).expect("a valid spec");
    for &scene_spec in SCENES {
        let built = occult_scenes::parse_spec(scene_spec)
            .and_then(|s| s.build())
            .expect("a generator scene");
        let scene = Arc::new(built.scene);
        let views = views(&scene, built.default_camera);
        let mut reference = Algorithm::ZBUFFER
            .build(scene.clone(), &one_thread())
            .expect("zbuffer builds");
        let expected: Vec<Frame> = views
            .iter()
            .map(|v| {
                let mut f = Frame::new(v.width(), v.height()).expect("small frame");
                reference.render(v, &mut f).expect("zbuffer renders");
                f
            })
            .collect();
        for ranks in 1..=4 {
            let out = run_threads(ranks, |comm| {
                let options = sort_last_options(comm.clone(), one_thread(), config.clone());
                let mut r = spec.build(scene.clone(), &options).expect("builds on every rank");
                views
                    .iter()
                    .map(|v| {
                        let mut f = Frame::new(v.width(), v.height()).expect("small frame");
                        r.render(v, &mut f).expect("renders on every rank");
                        f
                    })
                    .collect::<Vec<_>>()
            });
            let frames = out.into_iter().next().expect("rank 0").expect("rank 0 does not panic");
            for (i, (f, e)) in frames.iter().zip(&expected).enumerate() {
                assert!(
                    f.items() == e.items() && f.depth().iter().zip(e.depth()).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{algo} on {scene_spec}, {ranks} ranks, view {i}: differs from zbuffer"
                );
            }
        }
    }
}

#[test]
fn zbuffer_sort_last_is_identical_on_every_generator() {
    check("zbuffer");
}

#[test]
fn frustum_sort_last_is_identical_on_every_generator() {
    check("frustum");
}

#[test]
fn hzb_sort_last_is_identical_on_every_generator() {
    check("hzb");
}

#[test]
fn lzb_sort_last_is_identical_on_every_generator() {
    check("lzb");
}

fn small_terrain() -> (Arc<Scene>, Camera) {
    let built = occult_scenes::parse_spec("terrain:g=8")
        .and_then(|s| s.build())
        .expect("a generator scene");
    (Arc::new(built.scene), built.default_camera)
}

#[test]
fn a_rank_that_fails_to_build_is_one_error_on_every_rank() {
    let (scene, _) = small_terrain();
    let out = run_threads(3, |comm| {
        let config = SortLastConfig {
            fail_rank: Some(1),
            ..SortLastConfig::default()
        };
        let options = sort_last_options(comm.clone(), one_thread(), config);
        Algorithm::ZBUFFER.build(scene.clone(), &options).map(|_| ())
    });
    for r in out {
        match r.expect("no rank panics") {
            Err(RenderError::Ranks(m)) => assert!(m.starts_with("rank 1 of 3: "), "{m}"),
            other => panic!("expected the rank's failure, got {other:?}"),
        }
    }
}

#[test]
fn a_frame_of_the_wrong_size_is_one_error_on_every_rank() {
    let (scene, camera) = small_terrain();
    let view = View::new(camera, 32, 32).expect("valid");
    let out = run_threads(2, |comm| {
        let options = sort_last_options(comm.clone(), one_thread(), SortLastConfig::default());
        let mut r = Algorithm::ZBUFFER.build(scene.clone(), &options).expect("builds");
        // Rank 1 passes a frame that does not match the view.
        let mut f = Frame::new(32 + comm.rank() as u32, 32).expect("small frame");
        r.render(&view, &mut f).map(|_| ())
    });
    for r in out {
        assert!(matches!(r.expect("no rank panics"), Err(RenderError::Ranks(m)) if m.starts_with("rank 1 of 2")));
    }
}

#[test]
fn nbuffer_and_oqgrid_sort_last_are_identical_on_every_generator() {
    check("nbuffer");
    check("oqgrid");
}

#[test]
fn parallel_lzb_is_identical_on_every_generator() {
    let config = SortLastConfig {
        parallel_lzb: true,
        ..SortLastConfig::default()
    };
    check_with("lzb:payoff=off", config.clone());
    check_with("lzb:payoff=off,oor=off,coherence=off,plane=dynamic", config);
}

#[test]
fn parallel_lzb_needs_payoff_off() {
    let (scene, _) = small_terrain();
    let out = run_threads(2, |comm| {
        let config = SortLastConfig {
            parallel_lzb: true,
            ..SortLastConfig::default()
        };
        let options = sort_last_options(comm.clone(), one_thread(), config);
        AlgoSpec::parse("lzb")
            .expect("valid")
            .build(scene.clone(), &options)
            .map(|_| ())
    });
    for r in out {
        assert!(matches!(r.expect("no rank panics"), Err(RenderError::Ranks(m)) if m.contains("payoff=off")));
    }
}
