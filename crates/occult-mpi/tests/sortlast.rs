//! Sort-last over thread ranks: frames bit-identical to the single-process `zbuffer` on every
//! generator at 1, 2, 3 and 4 ranks, for brute force and culling renderers; failures end every
//! rank with one error, never a hang, wherever in a frame a rank fails.

use std::panic::AssertUnwindSafe;
use std::sync::{mpsc, Arc, Barrier};
use std::time::{Duration, Instant};

use occult_core::{Camera, Scene, Vec3, View};
use occult_mpi::{run_threads, sort_last_options, Comm, Fault, SortLastConfig, ThreadComm};
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
            fault: Some("1".parse().expect("a valid fault")),
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
    check_with(
        "lzb:payoff=off,oor=off,coherence=off,plane=dynamic,caster=octree",
        config,
    );
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

/// How long the ranks of one failure case may take before the case counts as hung. They take
/// milliseconds; the bound times nothing, it turns a hang into a failed test.
const HANG: Duration = Duration::from_secs(120);

/// Runs `f` on `size` thread ranks, as [`run_threads`], but fails the test when they have not
/// all returned within [`HANG`] instead of waiting forever. Each rank keeps its end of the
/// group until every rank has returned, as an MPI process keeps its communicator until it
/// ends: a rank that returned early stays reachable, as under `mpirun` (with thread ranks its
/// channels would otherwise close, turning the others' wait into an error).
fn run_bounded<R: Send + 'static>(size: usize, f: impl Fn(&Arc<dyn Comm>) -> R + Send + Sync + 'static) -> Vec<R> {
    let f = Arc::new(f);
    let all_returned = Arc::new(Barrier::new(size));
    let (results, returned) = mpsc::channel();
    for comm in ThreadComm::group(size) {
        let (f, all_returned, results) = (Arc::clone(&f), Arc::clone(&all_returned), results.clone());
        std::thread::spawn(move || {
            let comm: Arc<dyn Comm> = Arc::new(comm);
            let out = std::panic::catch_unwind(AssertUnwindSafe(|| f(&comm)));
            // The test may have stopped listening (it failed): nothing to tell it then.
            let _ = results.send((comm.rank(), out.ok()));
            all_returned.wait();
        });
    }
    drop(results);
    let deadline = Instant::now() + HANG;
    let mut out: Vec<Option<R>> = (0..size).map(|_| None).collect();
    for _ in 0..size {
        match returned.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
            Ok((rank, Some(r))) => out[rank] = Some(r),
            Ok((rank, None)) => panic!("rank {rank} panicked"),
            Err(_) => {
                let waiting: Vec<usize> = (0..size).filter(|&r| out[r].is_none()).collect();
                panic!("ranks {waiting:?} of {size} did not return within {HANG:?}: they wait on a rank that failed");
            }
        }
    }
    out.into_iter().map(|r| r.expect("every rank returned")).collect()
}

/// Renders `frames` frames of `view` with `spec` built over `size` thread ranks with
/// `config`; on every rank, the frames it rendered before an error, and the error.
fn render_frames(
    size: usize,
    spec: &str,
    config: SortLastConfig,
    frames: usize,
    view_of: impl Fn(usize, usize) -> View + Send + Sync + 'static,
) -> Vec<(usize, Option<RenderError>)> {
    let (scene, _) = small_terrain();
    let spec = AlgoSpec::parse(spec).expect("a valid spec");
    run_bounded(size, move |comm| {
        let options = sort_last_options(comm.clone(), one_thread(), config.clone());
        let mut r = spec.build(scene.clone(), &options).expect("builds on every rank");
        for k in 0..frames {
            let view = view_of(comm.rank(), k);
            let mut f = Frame::new(view.width(), view.height()).expect("small frame");
            if let Err(e) = r.render(&view, &mut f) {
                return (k, Some(e));
            }
        }
        (frames, None)
    })
}

/// Asserts that every rank ended frame `frame` with the same error, `expected`.
fn assert_one_error(out: &[(usize, Option<RenderError>)], frame: usize, expected: &str, case: &str) {
    for (rank, (frames, e)) in out.iter().enumerate() {
        assert_eq!(*frames, frame, "{case}: rank {rank} ended at another frame ({e:?})");
        match e {
            Some(RenderError::Ranks(m)) => assert_eq!(m, expected, "{case}: rank {rank}"),
            other => panic!("{case}: rank {rank}: expected the failure, got {other:?}"),
        }
    }
}

/// The small terrain's view at 32×24 on every rank and frame, and the pixel-wider view of
/// `wider_rank` in frame 1.
fn small_views(wider_rank: Option<usize>) -> impl Fn(usize, usize) -> View + Send + Sync + 'static {
    let (_, camera) = small_terrain();
    move |rank, frame| {
        let wider = u32::from(wider_rank == Some(rank) && frame == 1);
        View::new(camera, 32 + wider, 24).expect("a valid view")
    }
}

/// For each of `sizes` ranks, the first and the last rank failing in frame 1 of 3 before
/// each of `agreements`, with and without replication: every rank ends frame 1 with the one
/// error naming the failed rank and the fault.
fn check_faults(spec: &str, parallel_lzb: bool, sizes: &[usize], agreements: impl Fn(bool) -> usize) {
    for &size in sizes {
        for failing in [0, size - 1] {
            for replicate in [false, true] {
                for agreement in 0..agreements(replicate) {
                    let fault = Fault {
                        rank: failing,
                        frame: Some(1),
                        agreement,
                    };
                    let config = SortLastConfig {
                        parallel_lzb,
                        replicate,
                        fault: Some(fault),
                    };
                    let out = render_frames(size, spec, config, 3, small_views(None));
                    let expected = format!("rank {failing} of {size}: failure injected for a test ({fault})");
                    let case = format!("{spec}, {size} ranks, rank {failing} fails at {fault}, replicate {replicate}");
                    assert_one_error(&out, 1, &expected, &case);
                }
            }
        }
    }
}

#[test]
fn parallel_lzb_ends_every_rank_with_one_error_when_a_rank_fails_mid_frame() {
    // Before the plane, the depth buffer and the PVL exchanges, (the replication,) and at the
    // frame's end.
    check_faults("lzb:payoff=off", true, &[2, 4], |replicate| 4 + usize::from(replicate));
}

#[test]
fn sort_last_ends_every_rank_with_one_error_when_a_rank_fails_in_a_frame() {
    // After rendering, and after compositing.
    check_faults("zbuffer", false, &[2, 3, 4], |_| 2);
}

#[test]
fn a_rank_whose_view_changes_size_mid_run_is_one_error_on_every_rank() {
    // The last rank's second frame is a pixel wider than the others': each rank renders its
    // own frame, and the compositing finds the messages of the wrong size.
    for size in [2, 3, 4] {
        let out = render_frames(
            size,
            "zbuffer",
            SortLastConfig::default(),
            3,
            small_views(Some(size - 1)),
        );
        let first = match &out[0].1 {
            Some(RenderError::Ranks(m)) => m.clone(),
            other => panic!("{size} ranks: expected a failure, got {other:?}"),
        };
        assert!(first.contains("frames of different sizes"), "{size} ranks: {first}");
        assert_one_error(&out, 1, &first, &format!("{size} ranks"));
    }
}

#[test]
fn rank_0_reports_the_exchange_split_and_sends_only_active_pixels() {
    let (scene, camera) = small_terrain();
    let view = View::new(camera, 64, 48).expect("a valid view");
    let out = run_threads(4, |comm| {
        let options = sort_last_options(comm.clone(), one_thread(), SortLastConfig::default());
        let mut r = Algorithm::ZBUFFER.build(scene.clone(), &options).expect("builds");
        let mut f = Frame::new(64, 48).expect("small frame");
        let stats = r.render(&view, &mut f).expect("renders");
        (stats, f.covered_pixel_count())
    });
    let (stats, covered) = out.into_iter().next().expect("rank 0").expect("no panic");
    let names: Vec<&str> = stats.counters.0.iter().map(|&(k, _)| k).collect();
    for counter in occult_mpi::sortlast::COUNTERS {
        assert!(names.contains(counter), "{counter} missing from {names:?}");
    }
    // Binary swap over 4 ranks sends at most a whole frame from its busiest rank (12 bytes a
    // pixel); with active pixels only, no more than the covered pixels and the run lengths.
    let pixels = 64 * 48;
    assert!(covered < pixels, "the view leaves some pixels empty");
    assert!(stats.counters.get("mpi_bytes_sent_max") < pixels * 12);
}
