//! Cancellation and progress ([`FrameControl`]) across every renderer: a cancelled frame is
//! [`RenderError::Cancelled`] wherever it is cancelled, leaves the renderer's frame-to-frame
//! state (visible lists, caches, planes) fit for the next frame, and a complete frame reports a
//! progress of 1. And preparation ([`Renderer::prepare`]) changes no frame.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use occult_core::{Affine3A, Camera, Instance, Scene, SceneBuilder, Vec3, View};
use occult_raster::Frame;

use crate::tests::cubes_on_ground;
use crate::{AlgoSpec, Algorithm, FrameControl, RenderError, RenderOptions, Renderer, ALGORITHMS};

/// Every renderer with its default settings, and the settings that keep other state between
/// frames or take other paths (threads, caches, occlusion batches, naive casting).
fn specs() -> Vec<String> {
    let mut specs: Vec<String> = ALGORITHMS.iter().map(|i| i.name.to_string()).collect();
    specs.extend(
        [
            // Without payoff: the culling itself, never a direct frame, on these small scenes.
            "hzb:payoff=off",
            "oqgrid:payoff=off",
            "nbuffer:payoff=off",
            "lzb:payoff=off",
            "hzb:parallel=hybrid,workers=2,payoff=off",
            "hzb:temporal=off,payoff=off",
            "lzb:pvl=triangles,select=dynamic",
            "lzb:mode=naive,plane=static",
            "oqgrid:grid=uniform",
            "oqgrid:queries=off",
            "oqgrid:parallel=columns,payoff=off",
            "oqgrid:parallel=columns",
            "hzb:parallel=columns,payoff=off",
            "nbuffer:test=query,hierarchy=flat",
            "rzb:cache=on",
            "rzb:occlude=off",
        ]
        .map(String::from),
    );
    specs
}

/// Cubes in rows on a ground: near ones hide far ones, so every culling renderer culls.
fn scene() -> Arc<Scene> {
    cubes_on_ground(
        [-12.0, 12.0, -30.0, 4.0],
        (0..5).flat_map(|x| (0..8).map(move |z| Vec3::new(-6.0 + 3.0 * x as f32, 0.0, -3.0 * z as f32))),
    )
}

/// Staggered walls of 4,608 triangles each, one mesh instanced: meshes large enough for the
/// renderers' own hierarchies (octrees, grids), where they check within a mesh.
fn walls() -> Arc<Scene> {
    let mut b = SceneBuilder::new();
    let wall = b
        .add_mesh("wall", crate::test_grid(48))
        .expect("a grid is a valid mesh");
    let instances = (0..6)
        .map(|i| Instance {
            parent_from_child: Affine3A::from_scale_rotation_translation(
                Vec3::new(5.0, 3.0, 1.0),
                glam::Quat::IDENTITY,
                Vec3::new(-7.0 + 2.5 * i as f32, -0.5, -4.0 * i as f32),
            ),
            child: wall,
        })
        .collect();
    let root = b.add_group("walls", instances).expect("a valid group");
    Arc::new(b.build(root).expect("a valid scene"))
}

/// A walk of views along and across the rows.
fn views(width: u32, height: u32) -> Vec<View> {
    [
        (Vec3::new(0.0, 0.6, 5.0), Vec3::new(0.0, 0.0, -20.0)),
        (Vec3::new(0.4, 0.7, 4.0), Vec3::new(0.5, 0.0, -20.0)),
        (Vec3::new(8.0, 3.0, 4.0), Vec3::new(0.0, 0.0, -12.0)),
        (Vec3::new(-1.5, 0.3, -4.0), Vec3::new(-1.0, 0.0, -25.0)),
    ]
    .iter()
    .map(|&(eye, target)| View::new(Camera::look_at(eye, target), width, height).expect("a valid test view"))
    .collect()
}

/// One-thread options watched by `control` (one thread: the checks come in one order).
fn options(control: &FrameControl) -> RenderOptions {
    let mut options = RenderOptions::default();
    options.raster.threads = 1;
    options.raster.control = control.clone();
    options
}

fn build(spec: &str, scene: &Arc<Scene>, options: &RenderOptions) -> Box<dyn Renderer> {
    AlgoSpec::parse(spec)
        .expect("a valid spec")
        .build(Arc::clone(scene), options)
        .expect("the renderer builds")
}

/// Renders `view` uncancelled into a new frame.
fn frame_of(r: &mut dyn Renderer, control: &FrameControl, view: &View) -> Frame {
    let mut frame = Frame::new(view.width(), view.height()).expect("a valid frame size");
    control.reset();
    r.render(view, &mut frame).expect("an uncancelled frame renders");
    if control.is_live() {
        assert_eq!(control.progress(), 1.0, "{}: a complete frame reports 1", r.name());
    }
    frame
}

fn same(a: &Frame, b: &Frame) -> bool {
    a.items() == b.items()
        && a.depth()
            .iter()
            .map(|d| d.to_bits())
            .eq(b.depth().iter().map(|d| d.to_bits()))
}

#[test]
fn every_renderer_refuses_a_frame_cancelled_before_it_begins() {
    let scene = scene();
    let view = &views(64, 48)[0];
    for info in ALGORITHMS {
        let control = FrameControl::new();
        let mut r = build(info.name, &scene, &options(&control));
        let mut frame = Frame::new(64, 48).expect("a valid frame size");
        control.cancel();
        match r.render(view, &mut frame) {
            Err(RenderError::Cancelled) => {}
            other => panic!("{}: a cancelled frame gave {:?}", info.name, other.map(|s| s.total)),
        }
        assert!(
            control.progress() < 1.0,
            "{}: a cancelled frame is not complete",
            info.name
        );
        assert_eq!(RenderError::Cancelled.to_string(), "frame cancelled");
        // The next frame, uncancelled, is whole.
        frame_of(&mut *r, &control, view);
    }
}

/// Cancels the second frame of a walk at its first check, then its second, ... until a frame
/// is no longer cancelled (it checked fewer times), on small meshes (cubes, where the
/// renderers check between batches) and on large ones (walls, where they check within their
/// hierarchies too): after each cancelled frame, the renderer
/// draws the rest of the walk as one that was never asked for it does (conservative renderers:
/// as `zbuffer`).
#[test]
fn a_frame_cancelled_at_any_check_leaves_the_renderer_as_it_was() {
    for scene in [scene(), walls()] {
        cancel_at_every_check(&scene);
    }
}

fn cancel_at_every_check(scene: &Arc<Scene>) {
    let views = views(64, 48);
    let inert = RenderOptions {
        raster: options(&FrameControl::default()).raster,
        ..RenderOptions::default()
    };
    let mut zbuffer = Algorithm::ZBUFFER
        .build(Arc::clone(scene), &inert)
        .expect("zbuffer builds");
    let reference: Vec<Frame> = views
        .iter()
        .map(|v| frame_of(&mut *zbuffer, &FrameControl::default(), v))
        .collect();
    for spec in specs() {
        let control = FrameControl::new();
        let options = options(&control);
        // The walk without a cancelled frame, for the approximate renderers.
        let mut plain = build(&spec, scene, &options);
        let expected: Vec<Frame> = if plain.is_conservative() {
            reference.clone()
        } else {
            views.iter().map(|v| frame_of(&mut *plain, &control, v)).collect()
        };
        let mut cancelled_count = 0;
        // Every check up to the 64th, then every sixteenth part further (oqgrid's grids check
        // thousands of times a frame).
        let mut k = 0u64;
        loop {
            k = if k < 64 { k + 1 } else { k + k / 16 };
            assert!(k < 1 << 20, "{spec}: a frame that checks without end");
            let mut r = build(&spec, scene, &options);
            assert!(
                same(&frame_of(&mut *r, &control, &views[0]), &expected[0]),
                "{spec}: frame 0"
            );
            let mut frame = Frame::new(64, 48).expect("a valid frame size");
            control.reset();
            control.cancel_at_check(k);
            match r.render(&views[1], &mut frame) {
                Err(RenderError::Cancelled) => {
                    cancelled_count += 1;
                    assert!(control.progress() < 1.0, "{spec}: cancelled at check {k} but reports 1");
                }
                Ok(_) => {
                    // Fewer than k checks: the frame is whole, and every check was tried.
                    assert!(same(&frame, &expected[1]), "{spec}: frame 1 uncancelled");
                    assert!(cancelled_count > 0, "{spec}: never checked");
                    break;
                }
                Err(e) => panic!("{spec}: {e}"),
            }
            for (i, view) in views.iter().enumerate().skip(1) {
                let f = frame_of(&mut *r, &control, view);
                assert!(
                    same(&f, &expected[i]),
                    "{spec}: frame {i} after a frame cancelled at check {k}"
                );
            }
        }
    }
}

/// The progress a watcher reads while frames render never decreases within a frame and ends
/// at 1; a frame cancelled halfway reports a fraction between 0 and 1.
#[test]
fn progress_rises_to_one_and_stops_short_when_cancelled() {
    let scene = scene();
    let views = views(256, 192);
    for spec in specs() {
        let control = FrameControl::new();
        let mut r = build(&spec, &scene, &options(&control));
        let done = AtomicBool::new(false);
        let readings = std::thread::scope(|s| {
            let watcher = s.spawn(|| {
                let mut readings = vec![control.progress()];
                while !done.load(Ordering::Relaxed) {
                    readings.push(control.progress());
                    std::thread::yield_now();
                }
                readings
            });
            let view = &views[1];
            let mut frame = Frame::new(view.width(), view.height()).expect("a valid frame size");
            r.render(view, &mut frame).expect("the frame renders");
            done.store(true, Ordering::Relaxed);
            watcher.join().expect("the watcher does not panic")
        });
        assert!(
            readings.windows(2).all(|w| w[0] <= w[1]),
            "{spec}: progress went back: {readings:?}"
        );
        assert_eq!(control.progress(), 1.0, "{spec}");
    }
    // lzb casts rays in waves of 4,096 pixels and reports after each: cancelled at a late check,
    // it has reported part of its frame.
    let control = FrameControl::new();
    let mut r = build("lzb:plane=static,plane_fraction=0.01", &scene, &options(&control));
    let mut frame = Frame::new(256, 192).expect("a valid frame size");
    let mut partial = false;
    for k in 1..1000 {
        control.reset();
        control.cancel_at_check(k);
        match r.render(&views[0], &mut frame) {
            Err(RenderError::Cancelled) => {
                let p = control.progress();
                assert!((0.0..1.0).contains(&p), "{p}");
                partial |= p > 0.0;
            }
            Ok(_) => break,
            Err(e) => panic!("{e}"),
        }
    }
    assert!(partial, "lzb reported no part of a cancelled frame");
}

/// Watched, `zbuffer` draws a scene of over 2^20 triangles in chunks: the same frame as in one
/// call, and a frame cancelled between two chunks has reported the first.
#[test]
fn zbuffer_in_chunks_draws_the_same_frame_and_reports_each() {
    let mut b = SceneBuilder::new();
    let tile = b.add_mesh("tile", crate::test_grid(8)).expect("a grid is a valid mesh");
    // 100 × 100 tiles of 128 triangles: 1,280,000 triangles, two chunks.
    let instances = (0..10_000)
        .map(|i| Instance {
            parent_from_child: Affine3A::from_translation(Vec3::new((i % 100) as f32, 0.0, -((i / 100) as f32))),
            child: tile,
        })
        .collect();
    let root = b.add_group("tiles", instances).expect("a valid group");
    let scene = Arc::new(b.build(root).expect("a valid scene"));
    let view = View::new(
        Camera::look_at(Vec3::new(50.0, 30.0, 20.0), Vec3::new(50.0, 0.0, -50.0)),
        64,
        48,
    )
    .expect("a valid view");
    let inert = FrameControl::default();
    let one_call = frame_of(&mut *build("zbuffer", &scene, &options(&inert)), &inert, &view);
    let control = FrameControl::new();
    let mut r = build("zbuffer", &scene, &options(&control));
    assert!(
        same(&frame_of(&mut *r, &control, &view), &one_call),
        "chunks draw the same frame"
    );
    // Checks: the frame's start, before the first chunk, before the second.
    control.reset();
    control.cancel_at_check(3);
    let mut frame = Frame::new(64, 48).expect("a valid frame size");
    assert!(matches!(r.render(&view, &mut frame), Err(RenderError::Cancelled)));
    let p = control.progress();
    assert!(p > 0.5 && p < 1.0, "the first chunk's 2^20 of 1,280,000 triangles: {p}");
}

/// `rzb:eps=auto` chooses ε from measured times, so its frames differ between runs and the
/// walks above cannot compare them; what a cancelled frame must leave as it was is checked
/// instead: §8.2's search and the frame count, whatever check the frame stops at.
#[test]
fn a_cancelled_rzb_frame_leaves_the_epsilon_search_as_it_was() {
    let scene = scene();
    let views = views(64, 48);
    let control = FrameControl::new();
    let params = AlgoSpec::parse("rzb:eps=auto").expect("a valid spec").params;
    let opts = crate::rzb::RzbOptions::from_params(&params).expect("valid rzb options");
    let mut cancelled = 0;
    for k in 1u64.. {
        assert!(k < 1 << 16, "a frame that checks without end");
        let mut r = crate::rzb::Rzb::with_options(Arc::clone(&scene), &options(&control), &opts).expect("rzb builds");
        frame_of(&mut r, &control, &views[0]);
        let before = r.learnt_state();
        let mut frame = Frame::new(64, 48).expect("a valid frame size");
        control.reset();
        control.cancel_at_check(k);
        match r.render(&views[1], &mut frame) {
            Err(RenderError::Cancelled) => {
                cancelled += 1;
                assert_eq!(r.learnt_state(), before, "cancelled at check {k}");
            }
            Ok(_) => {
                assert_ne!(r.learnt_state(), before, "a whole frame is learnt");
                assert!(cancelled > 0, "never checked");
                break;
            }
            Err(e) => panic!("{e}"),
        }
    }
}

/// [`Renderer::prepare`] changes no frame: every renderer prepared for one size draws the
/// frames an unprepared one draws, at that size and at another. A rasterizer on two threads
/// makes its sort-last private frame at preparation (`zbuffer`'s memory grows by it), and
/// `bands=N` each band's frame.
#[test]
fn a_prepared_renderer_draws_the_frames_an_unprepared_one_draws() {
    let scene = walls();
    let mut options = RenderOptions::default();
    options.raster.threads = 2;
    let control = options.raster.control.clone();
    // Forced sort-last as well: every large draw then reads the private frames made ahead.
    let mut sort_last = options.clone();
    sort_last.raster.strategy = occult_raster::Strategy::SortLast;
    let runs = specs()
        .into_iter()
        .map(|s| (s, &options))
        .chain(["zbuffer", "hzb:payoff=off", "oqgrid:payoff=off"].map(|s| (s.to_string(), &sort_last)))
        .chain(["hzb:bands=2", "oqgrid:bands=2,payoff=off"].map(|s| (s.to_string(), &options)));
    for (spec, options) in runs {
        let mut plain = build(&spec, &scene, options);
        let mut prepared = build(&spec, &scene, options);
        prepared.prepare(64, 48).expect("the renderer prepares");
        for view in views(64, 48).iter().chain(&views(48, 32)[..1]) {
            let a = frame_of(plain.as_mut(), &control, view);
            let b = frame_of(prepared.as_mut(), &control, view);
            assert!(same(&a, &b), "{spec}: a prepared renderer drew another frame");
        }
    }
    let mut z = build("zbuffer", &scene, &options);
    let before = z.memory_bytes();
    z.prepare(64, 48).expect("zbuffer prepares");
    let frame = 64 * 48 * (std::mem::size_of::<f32>() + std::mem::size_of::<occult_core::ItemId>());
    assert!(
        z.memory_bytes() >= before + frame,
        "the second thread's private frame is made at preparation"
    );
    let mut banded = build("zbuffer:bands=2", &scene, &options);
    let before = banded.memory_bytes();
    banded.prepare(64, 48).expect("bands prepare");
    assert!(
        banded.memory_bytes() >= before + 2 * frame,
        "each band's frame is made at preparation"
    );
}
