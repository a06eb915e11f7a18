//! Rasterizer invariants: watertightness, order/thread/tile independence, clipping, queries.

use occult_core::glam::Affine3A;
use occult_core::glam::{Mat4, Vec4};
use occult_core::{Aabb, Camera, Mesh, Vec3, View, NO_ITEM};
use occult_raster::{
    query_box, query_box_counted, Draw, DrawTriangles, Frame, RasterConfig, RasterCounts, RasterMode, Rasterizer,
    Strategy,
};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

fn raster(threads: usize, tile: u32) -> Rasterizer {
    raster_with(threads, tile, Strategy::Auto)
}

fn raster_with(threads: usize, tile: u32, strategy: Strategy) -> Rasterizer {
    Rasterizer::new(RasterConfig {
        threads,
        tile_size: tile,
        strategy,
        ..RasterConfig::default()
    })
    .unwrap()
}

/// One thread, and two with the small draws of these tests drawn directly (the automatic
/// strategy) or tile-binned.
const STRATEGIES: [(usize, Strategy); 3] = [(1, Strategy::Auto), (2, Strategy::Auto), (2, Strategy::Binned)];

fn draw_all(r: &mut Rasterizer, view: &View, mesh: &Mesh) -> Frame {
    draw_counted(r, view, mesh).0
}

/// The draw of every triangle of `mesh` seen by `view` as it is (item ids from 0).
fn whole_draw<'a>(mesh: &'a Mesh, view: &View) -> Draw<'a> {
    Draw {
        mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    }
}

/// [`draw_all`], with the draw's counts.
fn draw_counted(r: &mut Rasterizer, view: &View, mesh: &Mesh) -> (Frame, RasterCounts) {
    let mut f = Frame::new(view.width(), view.height()).unwrap();
    let d = whole_draw(mesh, view);
    let counts = r.draw(view, &mut f, &[d], RasterMode::Full);
    (f, counts)
}

/// A z = 0 grid whose vertices project exactly onto pixel centres and corners (camera at
/// z = 1, fov 90°, 64 × 64 pixels), so that many edges pass exactly through pixel centres:
/// the case the fill rule decides. `n × n` quads of 6 pixels, jittered by half-pixel steps.
fn grid_on_pixel_lattice(seed: u64) -> (Mesh, View) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let n = 13u32;
    let to_world = |px: f32| (px / 64.0 - 0.5) * 2.0;
    let mut p = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let mut x = -6.0 + 6.0 * i as f32;
            let mut y = -6.0 + 6.0 * j as f32;
            if i > 0 && i < n && j > 0 && j < n {
                x += rng.random_range(-2..=2) as f32 * 0.5;
                y += rng.random_range(-2..=2) as f32 * 0.5;
            }
            p.push(Vec3::new(to_world(x), -to_world(y), 0.0));
        }
    }
    let mut t = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            if rng.random_bool(0.5) {
                t.push([a, a + 1, a + n + 2]);
                t.push([a, a + n + 2, a + n + 1]);
            } else {
                t.push([a, a + 1, a + n + 1]);
                t.push([a + 1, a + n + 2, a + n + 1]);
            }
        }
    }
    let mut cam = Camera::look_at(Vec3::new(0.0, 0.0, 1.0), Vec3::ZERO);
    cam.fov_y_deg = 90.0;
    (Mesh::new(p, t).unwrap(), View::new(cam, 64, 64).unwrap())
}

/// How many times each pixel of `view` is covered when each triangle of `mesh` is drawn alone
/// into a fresh frame.
fn coverage_one_at_a_time(r: &mut Rasterizer, view: &View, mesh: &Mesh) -> Vec<u32> {
    let mut coverage = vec![0u32; (view.width() * view.height()) as usize];
    for t in 0..mesh.triangle_count() as u32 {
        let mut f = Frame::new(view.width(), view.height()).unwrap();
        let list = [t];
        let d = Draw {
            mesh,
            triangles: DrawTriangles::List(&list),
            clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
            first_item: 0,
        };
        r.draw(view, &mut f, &[d], RasterMode::Full);
        for (c, &i) in coverage.iter_mut().zip(f.items()) {
            *c += (i != NO_ITEM) as u32;
        }
    }
    coverage
}

#[test]
fn watertight_grid_covers_each_pixel_exactly_once() {
    for seed in 0..32 {
        let (mesh, view) = grid_on_pixel_lattice(seed);
        let coverage = coverage_one_at_a_time(&mut raster(1, 16), &view, &mesh);
        // The grid spans beyond the screen: every pixel is covered once, none twice.
        let mut histogram = [0; 4];
        coverage.iter().for_each(|&c| histogram[(c as usize).min(3)] += 1);
        assert_eq!(
            histogram,
            [0, 64 * 64, 0, 0],
            "seed {seed}: pixels covered 0, 1, 2, 3+ times"
        );
    }
}

#[test]
fn closed_sphere_front_faces_cover_once_with_backface_culling() {
    let (n, m) = (24u32, 48u32);
    let mut p = vec![Vec3::Y];
    for i in 1..n {
        let th = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..m {
            let ph = 2.0 * std::f32::consts::PI * j as f32 / m as f32;
            p.push(Vec3::new(th.sin() * ph.cos(), th.cos(), -th.sin() * ph.sin()));
        }
    }
    p.push(-Vec3::Y);
    let ring = |i: u32, j: u32| 1 + (i - 1) * m + (j % m);
    let mut t = Vec::new();
    for j in 0..m {
        t.push([0, ring(1, j), ring(1, j + 1)]);
        t.push([p.len() as u32 - 1, ring(n - 1, j + 1), ring(n - 1, j)]);
    }
    for i in 1..n - 1 {
        for j in 0..m {
            t.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
            t.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
        }
    }
    let mesh = Mesh::new(p, t).unwrap();
    let view = View::new(Camera::look_at(Vec3::new(0.3, 0.4, 3.0), Vec3::ZERO), 64, 64).unwrap();
    let mut culled = Rasterizer::new(RasterConfig {
        cull_backfaces: true,
        ..RasterConfig::default()
    })
    .unwrap();
    let coverage = coverage_one_at_a_time(&mut culled, &view, &mesh);
    let two_sided = draw_all(&mut raster(1, 64), &view, &mesh);
    for (c, &i) in coverage.iter().zip(two_sided.items()) {
        assert_eq!(*c, (i != NO_ITEM) as u32);
    }
    assert!(coverage.iter().filter(|&&c| c == 1).count() > 500);
}

fn soup(seed: u64, count: usize) -> Mesh {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut p = Vec::new();
    for _ in 0..count {
        let c = Vec3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
        );
        let s = rng.random_range(0.01f32..2.0).powi(2);
        for _ in 0..3 {
            p.push(
                c + Vec3::new(
                    rng.random_range(-s..s),
                    rng.random_range(-s..s),
                    rng.random_range(-s..s),
                ),
            );
        }
    }
    let t = (0..count as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    Mesh::new(p, t).unwrap()
}

fn random_view(rng: &mut Pcg64Mcg, w: u32, h: u32) -> View {
    loop {
        let eye = Vec3::new(
            rng.random_range(-6.0..6.0),
            rng.random_range(-6.0..6.0),
            rng.random_range(-6.0..6.0),
        );
        let target = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let mut cam = Camera::look_at(eye, target);
        cam.fov_y_deg = rng.random_range(20.0..100.0);
        cam.near = rng.random_range(0.01..1.0);
        cam.far = rng.random_range(3.0..20.0);
        if let Ok(v) = View::new(cam, w, h) {
            return v;
        }
    }
}

/// `order` as index-list draws of `chunk` triangles each.
fn list_draws<'a>(mesh: &'a Mesh, order: &'a [u32], chunk: usize, m: Mat4) -> Vec<Draw<'a>> {
    order
        .chunks(chunk)
        .map(|c| Draw {
            mesh,
            triangles: DrawTriangles::List(c),
            clip_from_object: m,
            first_item: 0,
        })
        .collect()
}

#[test]
fn frames_independent_of_order_threads_and_tiles() {
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    for seed in 0..12 {
        let mesh = soup(seed, 3000);
        let view = random_view(&mut rng, 173, 97);
        let reference = draw_all(&mut raster(1, 64), &view, &mesh);
        let mut order: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        order.shuffle(&mut rng);
        // Tile sizes matter to the tile-binned path only.
        for (threads, tile, simd, strategy) in [
            (1, 8, true, Strategy::Auto),
            (2, 16, false, Strategy::Binned),
            (3, 64, true, Strategy::Binned),
            (2, 1024, false, Strategy::Binned),
            (2, 64, true, Strategy::Auto),
            (1, 64, false, Strategy::Auto),
            (2, 64, true, Strategy::Banded),
            (3, 64, false, Strategy::Banded),
        ] {
            let mut r = Rasterizer::new(RasterConfig {
                threads,
                tile_size: tile,
                simd,
                strategy,
                ..RasterConfig::default()
            })
            .unwrap();
            let mut f = Frame::new(173, 97).unwrap();
            let m = view.clip_from_object(&Affine3A::IDENTITY);
            let draws = list_draws(&mesh, &order, 517, m);
            r.draw(&view, &mut f, &draws, RasterMode::Full);
            assert!(
                f.same_visibility(&reference),
                "seed {seed}, {threads} threads, {strategy:?}, tile {tile}, simd {simd}"
            );
        }
    }
}

#[test]
fn counts_do_not_depend_on_the_instruction_set() {
    // Fragments written depend on the order triangles reach a pixel: the 8-lane setup must hand
    // them over in the scalar path's order, those that need clipping included. The camera sits
    // inside the soup, so many triangles cross the near plane.
    let mut rng = Pcg64Mcg::seed_from_u64(21);
    for seed in 0..6 {
        let mesh = soup(100 + seed, 4000);
        let mut view = random_view(&mut rng, 157, 113);
        if seed % 2 == 0 {
            let mut cam = Camera::look_at(Vec3::new(0.1, 0.2, 0.3), Vec3::new(1.0, 0.5, -1.0));
            cam.near = 0.05;
            view = View::new(cam, 157, 113).unwrap();
        }
        let order: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        for strategy in [Strategy::Direct, Strategy::Binned, Strategy::SortLast, Strategy::Banded] {
            let counts: Vec<_> = [true, false]
                .map(|simd| {
                    let mut r = Rasterizer::new(RasterConfig {
                        threads: if strategy == Strategy::Direct { 1 } else { 2 },
                        tile_size: 16,
                        simd,
                        strategy,
                        ..RasterConfig::default()
                    })
                    .unwrap();
                    let m = view.clip_from_object(&Affine3A::IDENTITY);
                    let whole = [Draw {
                        mesh: &mesh,
                        triangles: DrawTriangles::All,
                        clip_from_object: m,
                        first_item: 0,
                    }];
                    let lists = list_draws(&mesh, &order, 37, m);
                    [&whole[..], &lists[..]].map(|draws| {
                        let mut f = Frame::new(157, 113).unwrap();
                        let c = r.draw(&view, &mut f, draws, RasterMode::Full);
                        (
                            c,
                            f.depth().iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                            f.items().to_vec(),
                        )
                    })
                })
                .into_iter()
                .collect();
            assert!(
                counts[0][0].0.fragments_written > 1000,
                "seed {seed}: the view shows the soup"
            );
            for (form, (a, b)) in ["whole", "lists"].iter().zip(counts[0].iter().zip(&counts[1])) {
                assert_eq!(a.0, b.0, "seed {seed}, {strategy:?}, {form}: counts, AVX2 and baseline");
                assert!(
                    a.1 == b.1 && a.2 == b.2,
                    "seed {seed}, {strategy:?}, {form}: frames differ"
                );
            }
        }
    }
}

/// Coplanar copies of large triangles (spans of every length, most fragments tying a stored
/// depth) drawn in shuffled orders: the nearest item wins every tie, and the eight-lane span
/// writes give the baseline's frame and counts.
#[test]
fn depth_ties_go_to_the_least_item_in_every_instruction_set() {
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO), 131, 97).unwrap();
    let mut p = Vec::new();
    let mut t = Vec::new();
    for _ in 0..40 {
        let c = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.2..0.2),
        );
        let s = rng.random_range(0.02..1.5);
        let corners = [c, c + Vec3::new(s, 0.1 * s, 0.05), c + Vec3::new(0.3 * s, s, -0.05)];
        // Three copies of each triangle: the same corners, the same depths, three items.
        for _ in 0..3 {
            let base = p.len() as u32;
            p.extend(corners);
            t.push([base, base + 1, base + 2]);
        }
    }
    let mesh = Mesh::new(p, t).unwrap();
    let mut order: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
    let m = view.clip_from_object(&Affine3A::IDENTITY);
    let mut first: Option<(Vec<u32>, Vec<u64>)> = None;
    for round in 0..4 {
        order.shuffle(&mut rng);
        let [a, b] = [true, false].map(|simd| {
            let mut r = Rasterizer::new(RasterConfig {
                threads: 1,
                simd,
                ..RasterConfig::default()
            })
            .unwrap();
            let mut f = Frame::new(131, 97).unwrap();
            let c = r.draw(&view, &mut f, &list_draws(&mesh, &order, 7, m), RasterMode::Full);
            // Of three coplanar copies, the first (least item) shows wherever the triangle does.
            assert!(
                f.items().iter().all(|&i| i == NO_ITEM || i % 3 == 0),
                "round {round}, simd {simd}"
            );
            (
                c,
                f.depth().iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                f.items().to_vec(),
            )
        });
        assert!(a.0.fragments_written > 2000, "round {round}: large spans drawn");
        assert_eq!(a.0, b.0, "round {round}: counts, AVX2 and baseline");
        assert!(a.1 == b.1 && a.2 == b.2, "round {round}: frames, AVX2 and baseline");
        let frame = (a.1, a.2);
        match &first {
            None => first = Some(frame),
            Some(f) => assert!(f == &frame, "round {round}: the frame depends on the order"),
        }
    }
}

#[test]
fn large_draws_are_identical_across_strategies() {
    // Above 200,000 triangles, several threads draw sort-last (direct workers and a merge);
    // one thread draws directly. They must agree (the forced strategies are tested below).
    let mut rng = Pcg64Mcg::seed_from_u64(99);
    let mesh = soup(5, 260_000);
    for _ in 0..3 {
        let view = random_view(&mut rng, 211, 133);
        let reference = draw_all(&mut raster(1, 64), &view, &mesh);
        assert!(reference.covered_pixel_count() > 1000);
        for (threads, simd) in [(2, true), (3, false), (4, true)] {
            let mut r = Rasterizer::new(RasterConfig {
                threads,
                simd,
                ..RasterConfig::default()
            })
            .unwrap();
            // Twice: the second draw reuses scratch frames that the first must have left clean.
            for _ in 0..2 {
                let f = draw_all(&mut r, &view, &mesh);
                assert!(f.same_visibility(&reference), "{threads} threads, simd {simd}");
            }
            // Depth-only as well.
            let mut a = Frame::new(211, 133).unwrap();
            let mut b = Frame::new(211, 133).unwrap();
            let d = whole_draw(&mesh, &view);
            r.draw(&view, &mut a, std::slice::from_ref(&d), RasterMode::DepthOnly);
            raster(1, 64).draw(&view, &mut b, std::slice::from_ref(&d), RasterMode::DepthOnly);
            assert!(a.depth().iter().zip(b.depth()).all(|(x, y)| x.to_bits() == y.to_bits()));
        }
    }
}

#[test]
fn coherent_large_draws_are_identical_across_strategies() {
    // A stream sorted along one axis: each sort-last block then touches a band of the frame, so
    // the merge reads and resets only some rows of a worker's frame. Alternating views check that
    // no scratch pixel outside those rows was left drawn.
    let soup = soup(8, 240_000);
    let mut tris: Vec<[Vec3; 3]> = (0..soup.triangle_count()).map(|t| soup.triangle_positions(t)).collect();
    tris.sort_by(|a, b| (a[0].y + a[1].y + a[2].y).total_cmp(&(b[0].y + b[1].y + b[2].y)));
    let positions: Vec<Vec3> = tris.iter().flatten().copied().collect();
    let t = (0..tris.len() as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    let mesh = Mesh::new(positions, t).unwrap();
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    let views: Vec<View> = (0..3).map(|_| random_view(&mut rng, 197, 141)).collect();
    let references: Vec<Frame> = views.iter().map(|v| draw_all(&mut raster(1, 64), v, &mesh)).collect();
    assert!(references.iter().all(|f| f.covered_pixel_count() > 1000));
    for threads in [2, 3] {
        let mut r = Rasterizer::new(RasterConfig {
            threads,
            strategy: Strategy::SortLast,
            ..RasterConfig::default()
        })
        .unwrap();
        for round in 0..2 {
            for (view, reference) in views.iter().zip(&references) {
                let f = draw_all(&mut r, view, &mesh);
                assert!(f.same_visibility(reference), "{threads} threads, round {round}");
            }
        }
    }
}

#[test]
fn depth_only_matches_full_depth() {
    let mesh = soup(3, 2000);
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    let view = random_view(&mut rng, 80, 60);
    let full = draw_all(&mut raster(0, 32), &view, &mesh);
    let mut f = Frame::new(80, 60).unwrap();
    let d = whole_draw(&mesh, &view);
    raster(0, 32).draw(&view, &mut f, &[d], RasterMode::DepthOnly);
    assert!(f
        .depth()
        .iter()
        .zip(full.depth())
        .all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// A square of half-size `s` at y = 0, facing up.
fn ground(s: f32) -> Mesh {
    Mesh::new(
        vec![
            Vec3::new(-s, 0.0, -s),
            Vec3::new(s, 0.0, -s),
            Vec3::new(s, 0.0, s),
            Vec3::new(-s, 0.0, s),
        ],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap()
}

#[test]
fn huge_ground_plane_crossing_near_plane_has_no_cracks() {
    let mesh = ground(1e6);
    let mut cam = Camera::look_at(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.8, -10.0));
    cam.far = 1e7;
    // Small frames too: a triangle reaching far into the guard band shows a tiny box there.
    for (w, h) in [(128u32, 96u32), (64, 48), (32, 32), (8, 8), (5, 3)] {
        let view = View::new(cam, w, h).unwrap();
        for (threads, strategy) in STRATEGIES {
            let f = draw_all(&mut raster_with(threads, 32, strategy), &view, &mesh);
            // Every pixel of the bottom half sees the ground.
            for y in h.div_ceil(2)..h {
                for x in 0..w {
                    assert_ne!(
                        f.items()[(y * w + x) as usize],
                        NO_ITEM,
                        "{w}x{h}, {threads} threads, {strategy:?}: crack at {x},{y}"
                    );
                }
            }
        }
    }
}

/// However far a ground plane reaches past the view, what the view shows of it is the same:
/// clipping must not lose a triangle to rounding in its distant corners.
#[test]
fn ground_plane_coverage_does_not_depend_on_its_size() {
    for near in [0.1, 10.0] {
        let mut cam = Camera::look_at(Vec3::new(0.0, 5.0, -20.0), Vec3::ZERO);
        (cam.near, cam.far) = (near, 100.0);
        let view = View::new(cam, 160, 120).unwrap();
        let mut covered = Vec::new();
        for s in [1e3f32, 1e5, 1e6, 3e6, 1e7, 1e8, 1e9] {
            let mesh = ground(s);
            for (threads, strategy) in STRATEGIES {
                covered.push((
                    s,
                    threads,
                    strategy,
                    draw_all(&mut raster_with(threads, 32, strategy), &view, &mesh).covered_pixel_count(),
                ));
            }
        }
        assert!(
            covered[0].3 > 160 * 120 / 4,
            "near {near}: the ground fills the view's lower part"
        );
        assert!(
            covered.iter().all(|c| c.3 == covered[0].3),
            "near {near}: covered pixels by half-size, threads and strategy: {covered:?}"
        );
    }
}

/// The scratch memory a rasterizer keeps is counted: projected vertices, and the private
/// frames of sort-last draws.
#[test]
fn memory_bytes_counts_the_scratch_memory() {
    let mesh = soup(3, 2000);
    let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 12.0), Vec3::ZERO), 96, 64).unwrap();
    let mut r = raster(1, 32);
    assert_eq!(r.memory_bytes(), 0, "nothing drawn yet");
    draw_all(&mut r, &view, &mesh);
    assert!(r.memory_bytes() >= mesh.positions().len() * 16, "{}", r.memory_bytes());
    let mut r = Rasterizer::new(RasterConfig {
        threads: 2,
        strategy: Strategy::SortLast,
        ..RasterConfig::default()
    })
    .unwrap();
    draw_all(&mut r, &view, &mesh);
    assert!(
        r.memory_bytes() >= 96 * 64 * 12 + mesh.positions().len() * 16,
        "{}",
        r.memory_bytes()
    );
}

/// A triangle that clipping cuts into pieces counts once as rasterized.
#[test]
fn clipped_triangles_count_once() {
    let mesh = ground(1e3);
    // Looking along the diagonal the two triangles share: both in view.
    let mut cam = Camera::look_at(Vec3::new(0.0, 1.0, 0.0), Vec3::new(-10.0, 0.8, -10.0));
    cam.far = 1e4;
    let view = View::new(cam, 64, 48).unwrap();
    for (threads, strategy) in [(1, Strategy::Direct), (2, Strategy::Binned), (2, Strategy::SortLast)] {
        let mut r = Rasterizer::new(RasterConfig {
            threads,
            strategy,
            ..RasterConfig::default()
        })
        .unwrap();
        let (_, counts) = draw_counted(&mut r, &view, &mesh);
        assert_eq!(
            (counts.triangles_submitted, counts.triangles_rasterized),
            (2, 2),
            "{strategy:?}: both cut by the near plane and the guard band"
        );
    }
}

#[test]
fn behind_camera_and_beyond_far_draw_nothing() {
    let mesh = soup(1, 500);
    let cam = Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::new(0.0, 0.0, 20.0));
    let view = View::new(cam, 64, 64).unwrap();
    assert_eq!(draw_all(&mut raster(1, 64), &view, &mesh).covered_pixel_count(), 0);
    let mut cam = Camera::look_at(Vec3::new(0.0, 0.0, 100.0), Vec3::ZERO);
    cam.far = 50.0;
    let view = View::new(cam, 64, 64).unwrap();
    assert_eq!(draw_all(&mut raster(1, 64), &view, &mesh).covered_pixel_count(), 0);
}

#[test]
fn degenerate_triangles_draw_nothing() {
    let mesh = Mesh::new(
        vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::Y],
        vec![[0, 1, 2], [3, 3, 3], [0, 0, 1]],
    )
    .unwrap();
    let view = View::new(
        Camera::look_at(Vec3::new(0.5, 0.5, 2.0), Vec3::new(0.5, 0.5, 0.0)),
        32,
        32,
    )
    .unwrap();
    let (f, c) = draw_counted(&mut raster(1, 8), &view, &mesh);
    assert_eq!(c.triangles_rasterized, 0);
    assert_eq!(f.covered_pixel_count(), 0);
}

#[test]
fn query_box_is_conservative() {
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let mut checked = 0;
    for seed in 0..40 {
        let occluders = soup(100 + seed, 400);
        let view = random_view(&mut rng, 96, 64);
        let base = draw_all(&mut raster(1, 32), &view, &occluders);
        for _ in 0..20 {
            let c = Vec3::new(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            );
            let e = Vec3::new(
                rng.random_range(0.01..1.0),
                rng.random_range(0.01..1.0),
                rng.random_range(0.01..1.0),
            );
            let b = Aabb::new(c - e, c + e);
            // Random triangles inside the box, some with corners on its faces.
            let mut p = Vec::new();
            for _ in 0..30 {
                let mut q = Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                if rng.random_bool(0.3) {
                    q[rng.random_range(0..3)] = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                }
                p.push(c + e * q);
            }
            let inner = Mesh::new(p, (0..10).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect()).unwrap();
            let mut f = base.clone();
            let d = Draw {
                mesh: &inner,
                triangles: DrawTriangles::All,
                clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
                first_item: 1_000_000,
            };
            let written = raster(1, 32)
                .draw(&view, &mut f, &[d], RasterMode::Full)
                .fragments_written;
            let clip_from_world = view.clip_from_object(&Affine3A::IDENTITY);
            let samples = query_box(&base, &view, &clip_from_world, &b);
            // The counted query: the same samples; its comparisons are the silhouette's pixels,
            // which do not depend on the depth (on a cleared frame every one of them passes).
            let counted = query_box_counted(&base, &view, &clip_from_world, &b);
            let on_empty = query_box_counted(&Frame::new(96, 64).unwrap(), &view, &clip_from_world, &b);
            assert_eq!(counted.samples, samples);
            assert!(counted.comparisons >= samples);
            assert_eq!(counted.comparisons, on_empty.comparisons);
            assert_eq!(on_empty.samples, on_empty.comparisons);
            if written > 0 {
                assert!(
                    samples > 0,
                    "box {b:?} reported hidden but {written} fragments were written"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 50, "too few visible boxes exercised: {checked}");
}

/// Maps object `(px, py, 0)` to the screen position `(px, py)` of a `w × h` frame (powers of two
/// keep it exact), at depth 0.5.
fn screen_from_pixels(w: u32, h: u32) -> Mat4 {
    Mat4::from_cols(
        Vec4::new(2.0 / w as f32, 0.0, 0.0, 0.0),
        Vec4::new(0.0, -2.0 / h as f32, 0.0, 0.0),
        Vec4::ZERO,
        Vec4::new(-1.0, 1.0, 0.5, 1.0),
    )
}

/// Exact coverage of a triangle given in pixels (multiples of 1/256): i128 edge functions at
/// pixel centres with the top-left rule.
fn reference_coverage(v: [(f64, f64); 3], w: u32, h: u32) -> Vec<bool> {
    let fx = |p: (f64, f64)| ((p.0 * 256.0) as i128, (p.1 * 256.0) as i128);
    let (mut a, mut b, mut c) = (fx(v[0]), fx(v[1]), fx(v[2]));
    let area = (b.0 - a.0) * (c.1 - a.1) - (c.0 - a.0) * (b.1 - a.1);
    if area < 0 {
        std::mem::swap(&mut b, &mut c);
    }
    let _ = &mut a;
    let corners = [a, b, c];
    let mut out = vec![false; (w * h) as usize];
    if area == 0 {
        return out;
    }
    for y in 0..h {
        for x in 0..w {
            let p = (x as i128 * 256 + 128, y as i128 * 256 + 128);
            out[(y * w + x) as usize] = (0..3).all(|i| {
                let (s, e) = (corners[i], corners[(i + 1) % 3]);
                let (ea, eb) = (s.1 - e.1, e.0 - s.0);
                let value = ea * (p.0 - s.0) + eb * (p.1 - s.1);
                value > 0 || (value == 0 && (ea > 0 || (ea == 0 && eb > 0)))
            });
        }
    }
    out
}

fn strategies() -> Vec<RasterConfig> {
    let mut v = vec![];
    for simd in [true, false] {
        v.push(RasterConfig {
            threads: 1,
            simd,
            strategy: Strategy::Direct,
            ..RasterConfig::default()
        });
        for tile in [8, 16, 64] {
            v.push(RasterConfig {
                threads: 2,
                tile_size: tile,
                simd,
                strategy: Strategy::Binned,
                ..RasterConfig::default()
            });
        }
        v.push(RasterConfig {
            threads: 2,
            simd,
            strategy: Strategy::SortLast,
            ..RasterConfig::default()
        });
        v.push(RasterConfig {
            threads: 3,
            simd,
            strategy: Strategy::SortLast,
            ..RasterConfig::default()
        });
    }
    v
}

fn draw_pixels(config: &RasterConfig, tris: &[[(f64, f64); 3]], w: u32, h: u32) -> Frame {
    let p: Vec<Vec3> = tris
        .iter()
        .flatten()
        .map(|&(x, y)| Vec3::new(x as f32, y as f32, 0.0))
        .collect();
    let t = (0..tris.len() as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    let mesh = Mesh::new(p, t).unwrap();
    let view = View::new(Camera::look_at(Vec3::Z, Vec3::ZERO), w, h).unwrap();
    let mut f = Frame::new(w, h).unwrap();
    let d = Draw {
        mesh: &mesh,
        triangles: DrawTriangles::All,
        clip_from_object: screen_from_pixels(w, h),
        first_item: 0,
    };
    Rasterizer::new(config.clone())
        .unwrap()
        .draw(&view, &mut f, &[d], RasterMode::Full);
    f
}

#[test]
fn coverage_matches_exact_reference_including_guard_band_triangles() {
    type Case = ([(f64, f64); 3], u32, u32);
    let mut cases: Vec<Case> = vec![
        // Whole-frame triangles far into the guard band, on tiny frames.
        ([(-2000.0, -2000.0), (4000.0, -2000.0), (-2000.0, 4000.0)], 64, 64),
        ([(-2000.0, -2000.0), (4000.0, -2000.0), (-2000.0, 4000.0)], 8, 8),
        ([(-2000.0, -2000.0), (4000.0, -2000.0), (-2000.0, 4000.0)], 4, 4),
        // A corner of a large frame: a long triangle whose on-screen box is small.
        ([(22.0, -2212.0), (-2702.0, 22.0), (22.0, 22.0)], 1024, 512),
        ([(41.0, 2212.0), (2702.0, 37.0), (41.0, 37.0)], 128, 64),
    ];
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    for _ in 0..150 {
        let (w, h) = (
            [4u32, 16, 64, 128][rng.random_range(0..4)],
            [4u32, 32, 64][rng.random_range(0..3)],
        );
        let big = rng.random_bool(0.5);
        let r = if big { 30000.0 } else { 40.0 };
        let q = |rng: &mut Pcg64Mcg| (rng.random_range(-r..r + w as f64) * 4.0).round() / 4.0;
        let mut tri = [(0.0, 0.0); 3];
        for c in &mut tri {
            *c = (q(&mut rng), q(&mut rng));
        }
        // Axis-aligned edges through pixel centres now and then.
        if rng.random_bool(0.3) {
            tri[1].1 = tri[0].1;
        }
        cases.push((tri, w, h));
    }
    for (tri, w, h) in cases {
        let expected = reference_coverage(tri, w, h);
        for config in strategies() {
            let f = draw_pixels(&config, &[tri], w, h);
            let got: Vec<bool> = f.items().iter().map(|&i| i != NO_ITEM).collect();
            let (e, g) = (
                expected.iter().filter(|&&c| c).count(),
                got.iter().filter(|&&c| c).count(),
            );
            assert!(
                got == expected,
                "{tri:?} on {w}x{h} with {config:?}: {g} pixels covered, exactly {e}"
            );
        }
    }
}

#[test]
fn every_strategy_draws_the_same_frame() {
    let mut rng = Pcg64Mcg::seed_from_u64(17);
    for _ in 0..4 {
        let (w, h) = (96, 64);
        let mut tris = vec![[(41.0, 2212.0), (2702.0, 37.0), (41.0, 37.0)]];
        for _ in 0..3000 {
            let c = (rng.random_range(-20.0..116.0), rng.random_range(-20.0..84.0));
            let s = rng.random_range(0.2f64..30.0);
            let mut t = [(0.0, 0.0); 3];
            for p in &mut t {
                *p = (
                    ((c.0 + rng.random_range(-s..s)) * 16.0).round() / 16.0,
                    ((c.1 + rng.random_range(-s..s)) * 16.0).round() / 16.0,
                );
            }
            tris.push(t);
        }
        let frames: Vec<Frame> = strategies().iter().map(|c| draw_pixels(c, &tris, w, h)).collect();
        for f in &frames[1..] {
            assert!(f.same_visibility(&frames[0]));
        }
    }
}

/// Jittered grids whose triangles are about a pixel across (the 8-lane setup forms their masks
/// of covered centres), in layers with holes that overdraw each other both ways, one of them
/// twice (depth ties broken by item), one tilted through the far plane, all reaching past the
/// frame's edges, with a larger triangle every few hundred: AVX2 and baseline give the same
/// frame and counts, the fragments written included (which depend on the order of writes),
/// directly and sort-last, with items and depth only.
#[test]
fn dense_tiny_triangles_match_the_baseline() {
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let (w, h) = (211, 97);
    let mut cam = Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
    cam.far = 7.0;
    let view = View::new(cam, w, h).unwrap();
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    // (depth at the left edge, at the right edge, cell size): layers in drawing order.
    let layers = [
        (-1.0, -3.0, 0.09),
        (0.5, 0.5, 0.08),
        (-0.5, -0.5, 0.07),
        (0.5, 0.5, 0.08),
        (1.0, 1.2, 0.05),
    ];
    for (layer, &(z0, z1, cell)) in layers.iter().enumerate() {
        let (nx, ny) = ((11.0f32 / cell) as u32, (6.0f32 / cell) as u32);
        let first = positions.len() as u32;
        let mut jitter = Pcg64Mcg::seed_from_u64(layer as u64 % 2);
        for j in 0..=ny {
            for i in 0..=nx {
                let (u, v) = (i as f32 / nx as f32, j as f32 / ny as f32);
                // Layer 3 is layer 1 again, vertex for vertex (same seed): its fragments tie.
                let (du, dv) = (jitter.random_range(-0.3..0.3), jitter.random_range(-0.3..0.3));
                positions.push(Vec3::new(
                    -5.5 + 11.0 * u + du * cell,
                    -3.0 + 6.0 * v + dv * cell,
                    z0 + (z1 - z0) * u,
                ));
            }
        }
        for j in 0..ny {
            for i in 0..nx {
                if layer > 0 && (i / 9 + j / 7) % 3 == 0 {
                    // Holes, through which the layers behind show.
                    continue;
                }
                let a = first + j * (nx + 1) + i;
                let (b, c, d) = (a + 1, a + nx + 1, a + nx + 2);
                triangles.push([a, b, d]);
                triangles.push([a, d, c]);
                if triangles.len() % 397 == 0 {
                    let p = positions.len() as u32;
                    let (x, y, z) = (
                        rng.random_range(-3.0..3.0),
                        rng.random_range(-2.0..2.0),
                        rng.random_range(-1.0..1.0),
                    );
                    let s = rng.random_range(0.2..1.5);
                    positions.extend([Vec3::new(x, y, z), Vec3::new(x + s, y, z), Vec3::new(x, y + s, z + 0.3)]);
                    triangles.push([p, p + 1, p + 2]);
                }
            }
        }
    }
    let mesh = Mesh::new(positions, triangles).unwrap();
    for (threads, strategy) in [(1, Strategy::Direct), (2, Strategy::SortLast)] {
        for mode in [RasterMode::Full, RasterMode::DepthOnly] {
            let [a, b] = [true, false].map(|simd| {
                let mut r = Rasterizer::new(RasterConfig {
                    threads,
                    simd,
                    strategy,
                    ..RasterConfig::default()
                })
                .unwrap();
                let mut f = Frame::new(w, h).unwrap();
                let d = whole_draw(&mesh, &view);
                let c = r.draw(&view, &mut f, &[d], mode);
                (c, f)
            });
            let what = format!("{threads} threads, {strategy:?}, {mode:?}");
            assert!(a.0.fragments_written > 40_000, "{what}: the grids cover the frame");
            assert_eq!(a.0, b.0, "{what}: counts, AVX2 and baseline");
            let bits = |f: &Frame| f.depth().iter().map(|d| d.to_bits()).collect::<Vec<_>>();
            assert!(bits(&a.1) == bits(&b.1), "{what}: depths");
            assert!(a.1.items() == b.1.items(), "{what}: items");
        }
    }
}
