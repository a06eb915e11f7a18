//! Tests of the strategy choice and of the passes of a draw.

use super::*;
use occult_core::{Affine3A, Camera, Vec3};

/// An `n × n` grid of quads of side `side`, centred on the origin in the plane z = 0.
fn grid(n: u32, side: f32) -> Mesh {
    let c = n as f32 * side / 2.0;
    let positions = (0..=n)
        .flat_map(|j| (0..=n).map(move |i| Vec3::new(i as f32 * side - c, j as f32 * side - c, 0.0)))
        .collect();
    let v = |i: u32, j: u32| j * (n + 1) + i;
    let triangles = (0..n)
        .flat_map(|j| {
            (0..n).flat_map(move |i| {
                [
                    [v(i, j), v(i + 1, j), v(i, j + 1)],
                    [v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)],
                ]
            })
        })
        .collect();
    Mesh::new(positions, triangles).expect("a grid of in-range triangles is a valid mesh")
}

/// On several threads, a fresh rasterizer's automatic strategy draws fewer than
/// [`SORT_LAST_MIN_TRIANGLES`] triangles directly on the calling thread, small or large,
/// with the binned path's frame and counts (but the triangles shared); larger draws go sort-last over the pool, and
/// forced strategies do what they say.
#[test]
fn small_draws_stay_on_the_calling_thread() {
    // One pixel is 2·10·tan 30° / 960 ≈ 0.012 units at the grid's distance.
    let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 1280, 960)
        .expect("a 1280x960 view of the grid");
    let (tiny, large) = (grid(60, 0.012), grid(20, 0.5));
    let whole = |mesh| Draw {
        mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let many: Vec<u32> = (0..SORT_LAST_MIN_TRIANGLES as u32).map(|i| i % 7200).collect();
    let sort_last = Draw {
        triangles: DrawTriangles::List(&many),
        ..whole(&tiny)
    };
    let pass = |strategy, draws: &[Draw<'_>]| {
        let mut frame = Frame::new(1280, 960).expect("a 1280x960 frame");
        let mut r = Rasterizer::new(RasterConfig {
            threads: 2,
            strategy,
            ..RasterConfig::default()
        })
        .expect("two threads and a strategy are a valid raster config");
        let counts = r.draw(&view, &mut frame, draws, RasterMode::Full);
        let (on_caller, used) = r.last_pass.expect("the draw recorded its pass");
        (on_caller, used, counts)
    };
    for mesh in [&tiny, &large] {
        let draw = [whole(mesh)];
        let (on_caller, used, auto) = pass(Strategy::Auto, &draw);
        assert!(
            on_caller && used == Strategy::Direct,
            "{} triangles",
            mesh.triangle_count()
        );
        let (on_caller, used, binned) = pass(Strategy::Binned, &draw);
        assert!(!on_caller && used == Strategy::Binned);
        assert!(auto.fragments_written > 1000);
        assert_eq!(auto.triangles_shared, 0, "on the caller");
        assert_eq!(
            binned.triangles_shared, binned.triangles_submitted,
            "binned over the pool"
        );
        let binned = RasterCounts {
            triangles_shared: 0,
            ..binned
        };
        assert_eq!(auto, binned, "{} triangles", mesh.triangle_count());
    }
    let (on_caller, used, _) = pass(Strategy::Auto, std::slice::from_ref(&sort_last));
    assert!(!on_caller && used == Strategy::SortLast, "large draws are shared");
    let (on_caller, used, _) = pass(Strategy::Direct, &[sort_last]);
    assert!(
        on_caller && used == Strategy::Direct,
        "forced direct stays on the caller"
    );
    // Frames: the same draw, automatic and binned.
    let draw = [whole(&tiny), whole(&large)];
    let mut frames = [
        Frame::new(1280, 960).expect("a 1280x960 frame"),
        Frame::new(1280, 960).expect("a 1280x960 frame"),
    ];
    for (f, strategy) in frames.iter_mut().zip([Strategy::Auto, Strategy::Binned]) {
        let mut r = Rasterizer::new(RasterConfig {
            threads: 2,
            strategy,
            ..RasterConfig::default()
        })
        .expect("two threads and a strategy are a valid raster config");
        r.draw(&view, f, &draw, RasterMode::Full);
    }
    assert_eq!(frames[0].items(), frames[1].items());
    assert!(frames[0]
        .depth()
        .iter()
        .zip(frames[1].depth())
        .all(|(x, y)| x.to_bits() == y.to_bits()));
}

/// Under the automatic strategy, a draw of fewer than [`SORT_LAST_MIN_TRIANGLES`] triangles is
/// shared when the rasterizer's measured cost of a triangle makes it long beside the frame,
/// and only then; draws go on being measured.
#[test]
fn long_small_draws_are_shared() {
    let view =
        View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 320, 240).expect("a valid 320 × 240 view");
    let mesh = grid(60, 0.03);
    let list: Vec<u32> = (0..SHARED_MIN_TRIANGLES as u32).collect();
    let draw = |n: usize| Draw {
        mesh: &mesh,
        triangles: DrawTriangles::List(&list[..n]),
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let mut r = Rasterizer::new(RasterConfig {
        threads: 2,
        ..RasterConfig::default()
    })
    .expect("a valid two-thread configuration");
    let mut frame = Frame::new(320, 240).expect("a 320 × 240 frame");
    let pixels = 320.0 * 240.0;
    let c = r.draw(&view, &mut frame, &[draw(SHARED_MIN_TRIANGLES)], RasterMode::Full);
    assert_eq!(r.last_pass, Some((true, Strategy::Direct)), "nothing measured yet");
    assert_eq!(c.triangles_shared, 0, "on the caller: none shared");
    assert!(r.triangle_ns() > 0.0, "the draw was measured");
    // One thread would take twice the threshold.
    let ns = 2.0 * SHARED_MIN_NS_PER_PIXEL * pixels / SHARED_MIN_TRIANGLES as f64;
    r.measured = (ns * 1000.0, 1000.0);
    let c = r.draw(&view, &mut frame, &[draw(SHARED_MIN_TRIANGLES)], RasterMode::Full);
    assert_eq!(r.last_pass, Some((false, Strategy::SortLast)), "long: shared");
    assert_eq!(c.triangles_shared, 0, "sort-last of one block: one worker's");
    // As long, but fill-bound (each triangle costing more than FILL_HEAVY_NS): bands.
    r.measured = (2.0 * FILL_HEAVY_NS * 1000.0, 1000.0);
    let c = r.draw(&view, &mut frame, &[draw(SHARED_MIN_TRIANGLES)], RasterMode::Full);
    assert_eq!(r.last_pass, Some((false, Strategy::Banded)), "fill-bound: bands");
    assert_eq!(c.triangles_shared, SHARED_MIN_TRIANGLES as u64, "bands: all shared");
    r.measured = (ns * 1000.0, 1000.0);
    r.draw(&view, &mut frame, &[draw(SHARED_MIN_TRIANGLES - 1)], RasterMode::Full);
    assert_eq!(
        r.last_pass,
        Some((false, Strategy::Banded)),
        "too few for sort-last, long enough for bands"
    );
    r.measured = (ns * 1000.0, 1000.0);
    r.draw(&view, &mut frame, &[draw(BANDED_MIN_TRIANGLES - 1)], RasterMode::Full);
    assert_eq!(r.last_pass, Some((true, Strategy::Direct)), "too few to judge");
    // Expected to take one thread less than BANDED_MIN_NS.
    let short = 0.5 * BANDED_MIN_NS / SHARED_MIN_TRIANGLES as f64;
    r.measured = (short * 1000.0, 1000.0);
    r.draw(&view, &mut frame, &[draw(SHARED_MIN_TRIANGLES)], RasterMode::Full);
    assert_eq!(r.last_pass, Some((true, Strategy::Direct)), "short: on the caller");
}

/// Whole-mesh draws of `meshes` seen by `view`, mesh `k` moved `k × dx` to the right and `k`
/// back, its items from `100,000 k`.
fn staggered<'a>(view: &View, meshes: &'a [Mesh], dx: f32) -> Vec<Draw<'a>> {
    meshes
        .iter()
        .enumerate()
        .map(|(k, mesh)| Draw {
            mesh,
            triangles: DrawTriangles::All,
            clip_from_object: view.clip_from_object(&Affine3A::from_translation(Vec3::new(
                dx * k as f32,
                0.0,
                -(k as f32),
            ))),
            first_item: 100_000 * k as u64,
        })
        .collect()
}

/// A banded draw gives the direct draw's frame and counts (its triangles counted shared), on
/// any number of threads, bands
/// split across every triangle size (tiny, spanning bands, larger than the frame).
#[test]
fn banded_draws_are_direct_draws() {
    let view =
        View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 301, 203).expect("a valid 301 × 203 view");
    let meshes = [grid(60, 0.01), grid(40, 0.08), grid(30, 0.25), grid(6, 4.0)];
    let draws = staggered(&view, &meshes, 0.3);
    let run = |threads, strategy| {
        let mut r = Rasterizer::new(RasterConfig {
            threads,
            strategy,
            ..RasterConfig::default()
        })
        .expect("a valid configuration");
        let mut frame = Frame::new(301, 203).expect("a 301 × 203 frame");
        let counts = r.draw(&view, &mut frame, &draws, RasterMode::Full);
        assert_eq!(r.last_pass.map(|p| p.1), Some(strategy), "{threads} threads");
        (counts, frame)
    };
    let (counts, frame) = run(1, Strategy::Direct);
    assert!(counts.fragments_written > 10_000, "the view shows the grids");
    for threads in [2, 3, 5] {
        let (c, f) = run(threads, Strategy::Banded);
        assert_eq!(c.triangles_shared, c.triangles_submitted, "{threads} threads");
        let c = RasterCounts {
            triangles_shared: 0,
            ..c
        };
        assert_eq!(c, counts, "{threads} threads");
        assert!(f.same_visibility(&frame), "{threads} threads");
        assert!(f
            .depth()
            .iter()
            .zip(frame.depth())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

/// A view restricted to a region ([`View::with_region`]) writes its pixels as the whole view
/// does and no other; a frame prepared for it ([`Rasterizer::clear_region`]) holds
/// [`crate::BLOCKED_DEPTH`] and no item elsewhere, and when the region moves, the pixels that
/// left it are blocked again.
#[test]
fn regions_draw_their_pixels_alone() {
    let view =
        View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 301, 203).expect("a valid 301 × 203 view");
    let meshes = [grid(60, 0.01), grid(30, 0.25), grid(6, 4.0)];
    let draws = staggered(&view, &meshes, 0.2);
    let mut r = Rasterizer::new(RasterConfig {
        threads: 1,
        ..RasterConfig::default()
    })
    .expect("a valid configuration");
    let mut whole = Frame::new(301, 203).expect("a frame");
    r.draw(&view, &mut whole, &draws, RasterMode::Full);
    let mut frame = Frame::new(301, 203).expect("a frame");
    let regions = [
        (0..301, 40..90),
        (0..301, 70..140),
        (100..150, 0..203),
        (120..301, 0..203),
        (0..20, 180..203),
        (0..301, 0..203),
    ];
    for (columns, rows) in regions {
        let band = view
            .with_region(columns.clone(), rows.clone())
            .expect("a region of the view");
        r.clear_region(&mut frame, [columns.start, rows.start, columns.end, rows.end]);
        assert_eq!(frame.region(), [columns.start, rows.start, columns.end, rows.end]);
        r.draw(&band, &mut frame, &draws, RasterMode::Full);
        for y in 0..203u32 {
            for x in 0..301u32 {
                let i = (y * 301 + x) as usize;
                if rows.contains(&y) && columns.contains(&x) {
                    assert_eq!(
                        frame.items()[i],
                        whole.items()[i],
                        "({x}, {y}) in {columns:?} × {rows:?}"
                    );
                    assert_eq!(frame.depth()[i].to_bits(), whole.depth()[i].to_bits());
                } else {
                    assert_eq!(
                        frame.items()[i],
                        occult_core::NO_ITEM,
                        "({x}, {y}) beside {columns:?} × {rows:?}"
                    );
                    assert_eq!(
                        frame.depth()[i],
                        crate::BLOCKED_DEPTH,
                        "({x}, {y}) beside {columns:?} × {rows:?}"
                    );
                }
            }
        }
    }
    assert!(frame.same_visibility(&whole));
    assert!(view.with_region(10..10, 0..10).is_err() && view.with_region(0..10, 0..204).is_err());
}

/// A sort-last draw and a clear finish, with the frame and counts of one thread, while one
/// of the rasterizer's two threads is blocked elsewhere: the other runs every job.
#[test]
fn draws_finish_while_a_pool_thread_is_blocked() {
    use std::sync::mpsc::channel;
    use std::time::Duration;
    let view =
        View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 320, 240).expect("a valid 320 × 240 view");
    // 2 · 320² triangles: above the sort-last threshold.
    let mesh = grid(320, 0.03);
    assert!(mesh.triangle_count() >= SORT_LAST_MIN_TRIANGLES);
    let draw = [Draw {
        mesh: &mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    }];
    let drawn = |r: &mut Rasterizer| {
        let mut frame = Frame::new(320, 240).expect("a 320 × 240 frame");
        r.clear(&mut frame);
        let counts = r.draw(&view, &mut frame, &draw, RasterMode::Full);
        (counts, frame)
    };
    let (one, one_frame) = drawn(
        &mut Rasterizer::new(RasterConfig {
            threads: 1,
            ..RasterConfig::default()
        })
        .expect("a one-thread rasterizer"),
    );
    let mut r = Rasterizer::new(RasterConfig {
        threads: 2,
        ..RasterConfig::default()
    })
    .expect("a two-thread rasterizer");
    let (release, blocked) = channel::<()>();
    let (started, has_started) = channel();
    r.install(|| {
        rayon::spawn(move || {
            let _ = started.send(());
            let _ = blocked.recv();
        })
    });
    has_started.recv().expect("the blocking task started");
    let (done, finished) = channel();
    std::thread::scope(|s| {
        s.spawn(|| {
            let result = drawn(&mut r);
            let _ = done.send((result, r.last_pass));
        });
        let result = finished.recv_timeout(Duration::from_secs(120));
        // Release the blocked thread whatever happened, so that a hung draw ends too.
        drop(release);
        let ((counts, frame), pass) = result.expect("the draw finished with one pool thread blocked");
        assert_eq!(pass, Some((false, Strategy::SortLast)));
        assert_eq!(counts.triangles_rasterized, one.triangles_rasterized);
        assert!(counts.fragments_written > 1000);
        assert_eq!(frame.items(), one_frame.items());
        assert!(frame
            .depth()
            .iter()
            .zip(one_frame.depth())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    });
}

/// Draws split into passes to bound the projected vertices give the frame and counts of
/// one pass.
#[test]
fn passes_bounding_projected_vertices_change_nothing() {
    let (w, h) = (96, 64);
    let view = View::new(
        Camera::look_at(Vec3::new(0.5, 1.0, 6.0), Vec3::new(0.0, 0.0, 0.0)),
        w,
        h,
    )
    .expect("a 96x64 view of the strip");
    // A strip of 40 quads (82 vertices) and a fan (11 vertices), each instanced thrice,
    // with an index-list draw between them.
    let strip = Mesh::new(
        (0..=40)
            .flat_map(|i| {
                [
                    Vec3::new(i as f32 * 0.1 - 2.0, 0.0, 0.0),
                    Vec3::new(i as f32 * 0.1 - 2.0, 1.0, 0.3),
                ]
            })
            .collect(),
        (0..40u32)
            .flat_map(|i| [[2 * i, 2 * i + 2, 2 * i + 1], [2 * i + 1, 2 * i + 2, 2 * i + 3]])
            .collect(),
    )
    .expect("a strip of in-range triangles is a valid mesh");
    let fan = Mesh::new(
        std::iter::once(Vec3::ZERO)
            .chain((0..10).map(|i| {
                let a = i as f32 * 0.6;
                Vec3::new(a.cos(), a.sin(), 0.2)
            }))
            .collect(),
        (1..10u32).map(|i| [0, i, i + 1]).collect(),
    )
    .expect("a fan of in-range triangles is a valid mesh");
    let list = [1u32, 5, 7, 30, 31];
    let mut draws = Vec::new();
    for k in 0..3 {
        let m = Affine3A::from_translation(Vec3::new(0.0, k as f32 * 0.4 - 0.6, -(k as f32)));
        for (mesh, triangles) in [
            (&strip, DrawTriangles::All),
            (&fan, DrawTriangles::All),
            (&strip, DrawTriangles::List(&list)),
        ] {
            draws.push(Draw {
                mesh,
                triangles,
                clip_from_object: view.clip_from_object(&m),
                first_item: draws.len() as u64 * 1000,
            });
        }
    }
    // Two threads bin: the automatic strategy would draw these small passes directly.
    for (threads, strategy) in [(1, Strategy::Auto), (2, Strategy::Binned)] {
        let mut r = Rasterizer::new(RasterConfig {
            threads,
            strategy,
            ..RasterConfig::default()
        })
        .expect("one or two threads and a strategy are a valid raster config");
        let vp = Viewport::new(&view, r.config());
        let pool = r.pool.clone();
        let mut runs = Vec::new();
        // One pass; each whole mesh alone (82 > 50 goes alone, two fans fit); every draw alone.
        for max_vertices in [usize::MAX, 50, 1] {
            let mut f = Frame::new(w, h).expect("a frame of the view's size");
            let shared = (threads > 1).then_some(Strategy::Binned);
            let mut pass = || r.draw_in_passes(&vp, &mut f, &draws, RasterMode::Full, max_vertices, shared);
            let counts = match pool.clone() {
                Some(p) => p.install(pass),
                None => pass(),
            };
            runs.push((counts, f));
        }
        assert!(runs[0].0.fragments_written > 500, "the view shows the draws");
        for (counts, f) in &runs[1..] {
            assert_eq!(counts.triangles_submitted, runs[0].0.triangles_submitted);
            assert_eq!(counts.triangles_rasterized, runs[0].0.triangles_rasterized);
            assert_eq!(f.items(), runs[0].1.items(), "{threads} threads");
            assert!(f
                .depth()
                .iter()
                .zip(runs[0].1.depth())
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }
}

/// The span bounds found with reciprocals are the divisions' exactly, on edge values as large
/// as the guard band allows, on exact multiples of the step (a centre on the edge) and next to
/// them.
#[test]
fn spans_without_divisions_are_the_divisions_spans() {
    use super::scan::{solve_span, solve_span_with, span_reciprocals};
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
    for case in 0..200_000 {
        let step = |rng: &mut rand_pcg::Pcg64Mcg| match rng.random_range(0..8) {
            0 => 0,
            1 => rng.random_range(-4i64..=4) * SUB,
            _ => rng.random_range(-(1i64 << 24)..(1i64 << 24)) * SUB,
        };
        let step_x = [step(&mut rng), step(&mut rng), step(&mut rng)];
        let row = std::array::from_fn(|k| {
            let s = step_x[k];
            match rng.random_range(0..3) {
                // On a pixel centre, or one off it.
                0 if s != 0 => -s * rng.random_range(-5000i64..5000) + rng.random_range(-1i64..=1),
                _ => rng.random_range(-(1i64 << 50)..(1i64 << 50)),
            }
        });
        let (lo, hi) = (rng.random_range(0i64..10), rng.random_range(0i64..9000));
        assert_eq!(
            solve_span_with(row, step_x, span_reciprocals(step_x), lo, hi),
            solve_span(row, step_x, lo, hi),
            "case {case}: {row:?} {step_x:?}"
        );
    }
}

/// A draw of some clusters of a mesh's [`Meshlets`] gives the frame and counts of a list
/// draw of the same triangles in the same order, under every strategy, with AVX2 and without
/// (the ranges that sort-last and tile binning hand out begin and end inside clusters); the
/// grid reaches through the near plane, so that clipped triangles take their corners from
/// the mesh.
#[test]
fn cluster_draws_are_list_draws() {
    let view = View::new(
        Camera::look_at(Vec3::new(0.3, -4.0, 1.5), Vec3::new(0.0, 2.0, 0.0)),
        320,
        240,
    )
    .expect("a 320 × 240 view of the grid");
    let mesh = grid(120, 0.1);
    // Clusters of 2 × 2 quads... and of uneven sizes, rows of quads, and an empty one.
    let mut triangles = Vec::new();
    let mut starts = vec![0u32];
    for t in (0..mesh.triangle_count() as u32).step_by(48) {
        let end = (t + 48 - (t / 48) % 5).min(mesh.triangle_count() as u32);
        triangles.extend(t..end);
        starts.push(triangles.len() as u32);
    }
    starts.push(triangles.len() as u32);
    let meshlets = Meshlets::new(&mesh, &triangles, &starts).expect("valid clusters");
    let mut list_of_clusters: Vec<u32> = (0..meshlets.len() as u32).filter(|c| c % 3 != 1).collect();
    list_of_clusters.reverse();
    let flat: Vec<u32> = list_of_clusters
        .iter()
        .flat_map(|&c| meshlets.triangles(c as usize).to_vec())
        .collect();
    let clip = view.clip_from_object(&Affine3A::IDENTITY);
    let as_clusters = Draw {
        mesh: &mesh,
        triangles: DrawTriangles::Clusters {
            meshlets: &meshlets,
            list: &list_of_clusters,
        },
        clip_from_object: clip,
        first_item: 5,
    };
    let as_list = Draw {
        triangles: DrawTriangles::List(&flat),
        ..as_clusters.clone()
    };
    assert_eq!(as_clusters.triangles.count(&mesh), flat.len());
    for simd in [true, false] {
        for strategy in [Strategy::Direct, Strategy::Binned, Strategy::SortLast, Strategy::Banded] {
            let draw = |d: &Draw<'_>| {
                let mut frame = Frame::new(320, 240).expect("a 320 × 240 frame");
                let mut r = Rasterizer::new(RasterConfig {
                    threads: 2,
                    strategy,
                    simd,
                    ..RasterConfig::default()
                })
                .expect("a valid configuration");
                let counts = r.draw(&view, &mut frame, std::slice::from_ref(d), RasterMode::Full);
                (frame, counts)
            };
            let (a, ca) = draw(&as_clusters);
            let (b, cb) = draw(&as_list);
            assert_eq!(ca, cb, "{strategy:?}, simd {simd}");
            assert!(ca.fragments_written > 1000, "{ca:?}");
            assert_eq!(a.items(), b.items(), "{strategy:?}, simd {simd}");
            assert!(a.depth().iter().zip(b.depth()).all(|(x, y)| x.to_bits() == y.to_bits()));
        }
    }
}

/// [`Rasterizer::take_written`] holds every pixel a draw wrote, whichever the strategy; a
/// draw wholly behind what is drawn writes none; taking it empties it.
#[test]
fn the_written_box_holds_every_pixel_written() {
    let view =
        View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 320, 240).expect("a valid 320 × 240 view");
    let (near, far) = (&grid(8, 0.2), &grid(40, 0.5));
    fn at<'a>(view: &View, z: f32, mesh: &'a Mesh, first_item: u64) -> Draw<'a> {
        Draw {
            mesh,
            triangles: DrawTriangles::All,
            clip_from_object: view.clip_from_object(&Affine3A::from_translation(Vec3::new(0.5, -0.3, z))),
            first_item,
        }
    }
    for strategy in [Strategy::Direct, Strategy::Binned, Strategy::SortLast, Strategy::Banded] {
        let mut r = Rasterizer::new(RasterConfig {
            threads: 2,
            strategy,
            ..RasterConfig::default()
        })
        .expect("a valid configuration");
        let mut frame = Frame::new(320, 240).expect("a 320 × 240 frame");
        assert_eq!(r.take_written(), None, "{strategy:?}: nothing drawn yet");
        r.draw(&view, &mut frame, &[at(&view, 1.0, near, 0)], RasterMode::Full);
        let b = r.take_written().expect("the near grid is in view");
        let mut written = 0;
        for y in 0..240u32 {
            for x in 0..320u32 {
                if frame.items()[(y * 320 + x) as usize] != occult_core::NO_ITEM {
                    written += 1;
                    assert!(
                        x >= b.x0 && x < b.x1 && y >= b.y0 && y < b.y1,
                        "{strategy:?}: ({x}, {y}) beside {b:?}"
                    );
                }
            }
        }
        assert!(
            written > 100 && b.area() < 320 * 240 / 2,
            "{strategy:?}: {written} in {b:?}"
        );
        assert_eq!(r.take_written(), None, "{strategy:?}: taken");
        // Behind the near grid and within its box: nothing passes the depth test.
        let small_far = Draw {
            triangles: DrawTriangles::Range(0..2),
            ..at(&view, -5.0, near, 1000)
        };
        r.draw(&view, &mut frame, &[small_far], RasterMode::Full);
        assert_eq!(r.take_written(), None, "{strategy:?}: hidden");
        // A far grid around it writes around it.
        r.draw(&view, &mut frame, &[at(&view, -5.0, far, 5000)], RasterMode::Full);
        assert!(r.take_written().is_some_and(|w| w.area() > b.area()), "{strategy:?}");
    }
}
