//! Rasterizer invariants: watertightness, order/thread/tile independence, clipping, queries.

use occult_core::glam::Affine3A;
use occult_core::{Aabb, Camera, Mesh, Vec3, View, NO_ITEM};
use occult_raster::{query_box, Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

fn raster(threads: usize, tile: u32) -> Rasterizer {
    Rasterizer::new(RasterConfig {
        threads,
        tile_size: tile,
        ..RasterConfig::default()
    })
    .unwrap()
}

fn draw_all(r: &mut Rasterizer, view: &View, mesh: &Mesh) -> Frame {
    let mut f = Frame::new(view.width(), view.height()).unwrap();
    let d = Draw {
        mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    r.draw(view, &mut f, &[d], RasterMode::Full);
    f
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

#[test]
fn watertight_grid_covers_each_pixel_exactly_once() {
    for seed in 0..32 {
        let (mesh, view) = grid_on_pixel_lattice(seed);
        let mut coverage = vec![0u32; 64 * 64];
        let mut r = raster(1, 16);
        for t in 0..mesh.triangle_count() as u32 {
            let mut f = Frame::new(64, 64).unwrap();
            let list = [t];
            let d = Draw {
                mesh: &mesh,
                triangles: DrawTriangles::List(&list),
                clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
                first_item: 0,
            };
            r.draw(&view, &mut f, &[d], RasterMode::Full);
            for (c, &i) in coverage.iter_mut().zip(f.items()) {
                *c += (i != NO_ITEM) as u32;
            }
        }
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
    let mut coverage = vec![0u32; 64 * 64];
    for tri in 0..mesh.triangle_count() as u32 {
        let mut f = Frame::new(64, 64).unwrap();
        let list = [tri];
        let d = Draw {
            mesh: &mesh,
            triangles: DrawTriangles::List(&list),
            clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
            first_item: 0,
        };
        culled.draw(&view, &mut f, &[d], RasterMode::Full);
        for (c, &i) in coverage.iter_mut().zip(f.items()) {
            *c += (i != NO_ITEM) as u32;
        }
    }
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

#[test]
fn frames_independent_of_order_threads_and_tiles() {
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    for seed in 0..12 {
        let mesh = soup(seed, 3000);
        let view = random_view(&mut rng, 173, 97);
        let reference = draw_all(&mut raster(1, 64), &view, &mesh);
        let mut order: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        order.shuffle(&mut rng);
        for (threads, tile, simd) in [
            (1, 8, true),
            (2, 16, false),
            (3, 64, true),
            (2, 1024, false),
            (1, 64, false),
        ] {
            let mut r = Rasterizer::new(RasterConfig {
                threads,
                tile_size: tile,
                simd,
                ..RasterConfig::default()
            })
            .unwrap();
            let mut f = Frame::new(173, 97).unwrap();
            let m = view.clip_from_object(&Affine3A::IDENTITY);
            let draws: Vec<Draw> = order
                .chunks(517)
                .map(|c| Draw {
                    mesh: &mesh,
                    triangles: DrawTriangles::List(c),
                    clip_from_object: m,
                    first_item: 0,
                })
                .collect();
            r.draw(&view, &mut f, &draws, RasterMode::Full);
            assert!(
                f.same_visibility(&reference),
                "seed {seed}, {threads} threads, tile {tile}, simd {simd}"
            );
        }
    }
}

#[test]
fn large_draws_are_identical_across_strategies() {
    // Above 200,000 triangles, several threads draw sort-last (direct workers and a merge);
    // one thread draws directly; small draws go tile-binned. All must agree.
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
            let d = Draw {
                mesh: &mesh,
                triangles: DrawTriangles::All,
                clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
                first_item: 0,
            };
            r.draw(&view, &mut a, std::slice::from_ref(&d), RasterMode::DepthOnly);
            raster(1, 64).draw(&view, &mut b, std::slice::from_ref(&d), RasterMode::DepthOnly);
            assert!(a.depth().iter().zip(b.depth()).all(|(x, y)| x.to_bits() == y.to_bits()));
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
    let d = Draw {
        mesh: &mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    raster(0, 32).draw(&view, &mut f, &[d], RasterMode::DepthOnly);
    assert!(f
        .depth()
        .iter()
        .zip(full.depth())
        .all(|(a, b)| a.to_bits() == b.to_bits()));
}

#[test]
fn huge_ground_plane_crossing_near_plane_has_no_cracks() {
    let s = 1e6;
    let mesh = Mesh::new(
        vec![
            Vec3::new(-s, 0.0, -s),
            Vec3::new(s, 0.0, -s),
            Vec3::new(s, 0.0, s),
            Vec3::new(-s, 0.0, s),
        ],
        vec![[0, 2, 1], [0, 3, 2]],
    )
    .unwrap();
    let mut cam = Camera::look_at(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.8, -10.0));
    cam.far = 1e7;
    let view = View::new(cam, 128, 96).unwrap();
    let f = draw_all(&mut raster(2, 32), &view, &mesh);
    // Every pixel of the bottom half sees the ground.
    for y in 48..96 {
        for x in 0..128 {
            assert_ne!(f.items()[y * 128 + x], NO_ITEM, "crack at {x},{y}");
        }
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
    let mut r = raster(1, 8);
    let mut f = Frame::new(32, 32).unwrap();
    let d = Draw {
        mesh: &mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let c = r.draw(&view, &mut f, &[d], RasterMode::Full);
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
            let samples = query_box(&base, &view, &view.clip_from_object(&Affine3A::IDENTITY), &b);
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
