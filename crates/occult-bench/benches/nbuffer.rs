//! N-buffer (Décoret 2005): build time per resolution (the paper's Table 1: 256², 512²,
//! 640×480, 1024²) on 1 and 2 threads, and rectangle queries per second on one core
//! (against Intel MOC's `TestRect`, 43–46 M/s per core here).
//!
//! The depth map is a synthetic reversed-Z map (a tilted plane with boxes, some pixels
//! empty); build time depends only on resolution and level count. Query workloads are
//! 1 M precomputed rectangles, sides 1–128 px at uniform random positions (`random`), or the
//! same sizes on a random walk (`coherent`: each rectangle near the previous one, as the
//! objects of a hierarchy are tested). Each workload runs one query at a time (`query_four`,
//! `query_one`, `occludes`) and batched (`query_four_batch`, `occludes_batch`).
//!
//! Particles (§3.2): 10^6 sprites among `city`, drawn all or culled (batched or one test call
//! each). Shadows (§3.3, §4.4): the stencil pass alone (`ShadowVolumes::stencil`) of the
//! unclamped and clamped volumes of `terrain` and `city:detail=1` from their default views
//! at 640×480, with the stencil fragments (the fill rate) printed beside.

use criterion::measurement::WallTime;
use criterion::{criterion_group, criterion_main, BenchmarkGroup, Criterion, Throughput};
use occult_raster::{Extremum, NBuffer, PixelRect, RasterConfig, Rasterizer};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

fn depth_map(w: u32, h: u32) -> Vec<f32> {
    let mut rng = Pcg64Mcg::seed_from_u64(7);
    let mut d: Vec<f32> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            0.01 + 0.5 * y / h as f32 + 0.1 * x / w as f32
        })
        .collect();
    for _ in 0..200 {
        let (x0, y0) = (rng.random_range(0..w), rng.random_range(0..h));
        let (bw, bh) = (rng.random_range(1..64), rng.random_range(1..64));
        let z: f32 = rng.random_range(0.0..1.0);
        for y in y0..(y0 + bh).min(h) {
            for x in x0..(x0 + bw).min(w) {
                d[(y * w + x) as usize] = z;
            }
        }
    }
    d
}

/// The build cases of `nbuffer_build` and `nbuffer_best`: every resolution of the paper's
/// Table 1 on 1 and 2 threads, the default level count. Sets `group`'s throughput to the
/// case's pixels, then calls `bench` with the group, the case's name
/// (`WxH/levels=L/threads=T`) and one rebuild of the case's N-buffer.
fn for_each_build_case(
    group: &mut BenchmarkGroup<'_, WallTime>,
    mut bench: impl FnMut(&mut BenchmarkGroup<'_, WallTime>, String, &mut dyn FnMut()),
) {
    for (w, h) in [(256u32, 256u32), (512, 512), (640, 480), (1024, 1024)] {
        let depth = depth_map(w, h);
        let levels = NBuffer::default_level_count(w, h);
        for threads in [1, 2] {
            let raster = Rasterizer::new(RasterConfig {
                threads,
                ..RasterConfig::default()
            })
            .expect("valid config");
            let mut nb = NBuffer::new(Extremum::Min, &depth, w, h).expect("valid size");
            group.throughput(Throughput::Elements(u64::from(w * h)));
            bench(group, format!("{w}x{h}/levels={levels}/threads={threads}"), &mut || {
                raster.install(|| nb.rebuild(&depth, w, h, levels).expect("valid size"))
            });
        }
    }
}

/// The query workloads of `nbuffer_query` and `nbuffer_best`, one at a time: an N-buffer of
/// two resolutions, each with random and coherent rectangles (see [`rects`]). Calls `bench`
/// with the workload's name (`WxH/random` or `WxH/coherent`), the N-buffer and the
/// rectangles with their nearest depths.
fn for_each_query_workload(mut bench: impl FnMut(String, &NBuffer, &[(PixelRect, f32)])) {
    for (w, h) in [(640u32, 480u32), (1024, 1024)] {
        let depth = depth_map(w, h);
        let nb = NBuffer::new(Extremum::Min, &depth, w, h).expect("valid size");
        for coherent in [false, true] {
            let rs = rects(w, h, coherent);
            let kind = if coherent { "coherent" } else { "random" };
            bench(format!("{w}x{h}/{kind}"), &nb, &rs);
        }
    }
}

fn build(c: &mut Criterion) {
    let mut group = c.benchmark_group("nbuffer_build");
    group.sample_size(30);
    for_each_build_case(&mut group, |group, name, rebuild| {
        group.bench_function(name, |b| b.iter(&mut *rebuild));
    });
    group.finish();
}

fn rects(w: u32, h: u32, coherent: bool) -> Vec<(PixelRect, f32)> {
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let (mut cx, mut cy) = (w / 2, h / 2);
    (0..1_000_000)
        .map(|_| {
            let (rw, rh) = (rng.random_range(1..=128u32), rng.random_range(1..=128u32));
            if coherent {
                cx = (cx as i64 + rng.random_range(-16..=16)).clamp(0, w as i64 - 1) as u32;
                cy = (cy as i64 + rng.random_range(-16..=16)).clamp(0, h as i64 - 1) as u32;
            } else {
                cx = rng.random_range(0..w);
                cy = rng.random_range(0..h);
            }
            let r = PixelRect {
                x0: cx,
                y0: cy,
                x1: cx + rw,
                y1: cy + rh,
            };
            (r, rng.random_range(0.0..1.0f32))
        })
        .collect()
}

fn queries(c: &mut Criterion) {
    let mut group = c.benchmark_group("nbuffer_query");
    group.sample_size(20);
    for_each_query_workload(|workload, nb, rs| {
        group.throughput(Throughput::Elements(rs.len() as u64));
        group.bench_function(format!("{workload}/query_four"), |b| {
            b.iter(|| {
                rs.iter()
                    .map(|&(r, _)| nb.query_four(r).depth)
                    .fold(0.0f32, |a, d| a + d)
            })
        });
        group.bench_function(format!("{workload}/query_one"), |b| {
            b.iter(|| {
                rs.iter()
                    .map(|&(r, _)| nb.query_one(r).depth)
                    .fold(0.0f32, |a, d| a + d)
            })
        });
        group.bench_function(format!("{workload}/occludes"), |b| {
            b.iter(|| rs.iter().map(|&(r, z)| usize::from(nb.occludes(r, z).0)).sum::<usize>())
        });
        // The same rectangles through the batched API (same answers, lookups overlapped).
        let rects: Vec<PixelRect> = rs.iter().map(|p| p.0).collect();
        let nearest: Vec<f32> = rs.iter().map(|p| p.1).collect();
        let mut out = vec![0.0f32; rs.len()];
        let mut hidden = vec![false; rs.len()];
        group.bench_function(format!("{workload}/query_four_batch"), |b| {
            b.iter(|| nb.query_four_batch(&rects, &mut out).expect("equal lengths"))
        });
        group.bench_function(format!("{workload}/occludes_batch"), |b| {
            b.iter(|| nb.occludes_batch(&rects, &nearest, &mut hidden).expect("equal lengths"))
        });
    });
    group.finish();
}

/// Time of `work` over all of `items`, robust to the time slicing of a shared machine: the
/// items are cut into chunks of 16 K, every chunk is timed in each of `passes` passes over all
/// of them (so the caches hold what a single pass leaves), and the fastest time of each chunk
/// is summed.
fn best_of_chunks<T>(items: &[T], passes: usize, mut work: impl FnMut(&[T]) -> u64) -> std::time::Duration {
    let chunks: Vec<&[T]> = items.chunks(16 * 1024).collect();
    let mut best = vec![std::time::Duration::MAX; chunks.len()];
    let mut sink = 0u64;
    for _ in 0..passes {
        for (b, c) in best.iter_mut().zip(&chunks) {
            let t = std::time::Instant::now();
            sink = sink.wrapping_add(work(c));
            *b = (*b).min(t.elapsed());
        }
    }
    std::hint::black_box(sink);
    best.iter().sum()
}

/// The build and query figures of `nbuffer_build` / `nbuffer_query` measured as the fastest
/// run instead of criterion's typical one, which the other builds and tests on the 2 shared
/// cores inflate: a build's time is the fastest of 20 builds; a query workload's time is
/// [`best_of_chunks`] over 3 passes. The reported time per iteration is that best time.
fn best(c: &mut Criterion) {
    let mut group = c.benchmark_group("nbuffer_best");
    group.sample_size(10);
    for_each_build_case(&mut group, |group, name, rebuild| {
        group.bench_function(format!("build/{name}"), |b| {
            b.iter_custom(|iters| {
                let mut fastest = std::time::Duration::MAX;
                for _ in 0..20 {
                    let t = std::time::Instant::now();
                    rebuild();
                    fastest = fastest.min(t.elapsed());
                }
                fastest.mul_f64(iters as f64)
            })
        });
    });
    for_each_query_workload(|workload, nb, rs| {
        let rects: Vec<PixelRect> = rs.iter().map(|p| p.0).collect();
        let nearest: Vec<f32> = rs.iter().map(|p| p.1).collect();
        let index: Vec<usize> = (0..rs.len()).collect();
        let mut out = vec![0.0f32; rs.len()];
        let mut hidden = vec![false; rs.len()];
        group.throughput(Throughput::Elements(rs.len() as u64));
        let mut run = |name: &str, work: &mut dyn FnMut(&[usize]) -> u64| {
            group.bench_function(format!("query/{workload}/{name}"), |b| {
                b.iter_custom(|iters| best_of_chunks(&index, 3, &mut *work).mul_f64(iters as f64))
            });
        };
        run("query_four", &mut |c| {
            c.iter().map(|&i| nb.query_four(rs[i].0).depth.to_bits() as u64).sum()
        });
        run("query_one", &mut |c| {
            c.iter().map(|&i| nb.query_one(rs[i].0).depth.to_bits() as u64).sum()
        });
        run("occludes", &mut |c| {
            c.iter().map(|&i| u64::from(nb.occludes(rs[i].0, rs[i].1).0)).sum()
        });
        run("query_four_batch", &mut |c| {
            let r = c[0]..c[0] + c.len();
            nb.query_four_batch(&rects[r.clone()], &mut out[r])
                .expect("equal lengths")
        });
        run("occludes_batch", &mut |c| {
            let r = c[0]..c[0] + c.len();
            nb.occludes_batch(&rects[r.clone()], &nearest[r.clone()], &mut hidden[r])
                .expect("equal lengths")
        });
    });
    group.finish();
}

/// §3.2 / §4.3: 10^6 sprites (sides 1–64 px) among the `city` seen from its default camera at
/// 640×480: drawing them all against drawing the survivors of the N-buffer test (the N-buffer
/// build from the scene's depth included). The scene itself is drawn once, outside the timing.
/// Scene `spec` drawn by zbuffer from its default camera at 640×480.
fn drawn(
    spec: &str,
) -> (
    std::sync::Arc<occult_core::Scene>,
    occult_core::View,
    occult_raster::Frame,
) {
    let w = occult_bench::workload(spec);
    let scene = std::sync::Arc::new(w.scene);
    let view = occult_core::View::new(w.camera, 640, 480).expect("valid view");
    let mut z = occult_render::Algorithm::ZBUFFER
        .build(scene.clone(), &occult_render::RenderOptions::default())
        .expect("zbuffer");
    let mut frame = occult_raster::Frame::new(640, 480).expect("valid size");
    z.render(&view, &mut frame).expect("render");
    (scene, view, frame)
}

fn particles(c: &mut Criterion) {
    use occult_render::nbuffer::particles::{draw_particles, Particles};
    let (scene, view, base) = drawn("city");
    let mut raster = Rasterizer::new(RasterConfig::default()).expect("valid config");
    let mut group = c.benchmark_group("nbuffer_particles");
    group.sample_size(10);
    for pow2 in [false, true] {
        let p = Particles::scatter(&scene.bounds(), 1_000_000, 64, pow2, 0.3, 9).expect("particles");
        let sizes = if pow2 { "pow2" } else { "any" };
        // Draw all; cull with the batched tests; cull with one test call per sprite.
        for (cull, batched, mode) in [
            (false, true, "draw_all"),
            (true, true, "nbuffer_cull"),
            (true, false, "nbuffer_cull_single_calls"),
        ] {
            let name = format!("1M_sprites/{sizes}/{mode}");
            group.bench_function(name, |b| {
                b.iter_batched_ref(
                    || base.clone(),
                    |frame| {
                        let nb = cull.then(|| {
                            raster.install(|| {
                                NBuffer::with_levels(Extremum::Min, frame.depth(), 640, 480, p.levels_needed())
                                    .expect("valid size")
                            })
                        });
                        draw_particles(&mut raster, &view, frame, &p, scene.item_count(), nb.as_ref(), batched)
                            .expect("draw")
                    },
                    criterion::BatchSize::LargeInput,
                )
            });
        }
        let mut frame = base.clone();
        let nb = NBuffer::with_levels(Extremum::Min, base.depth(), 640, 480, p.levels_needed()).expect("valid size");
        let counts =
            draw_particles(&mut raster, &view, &mut frame, &p, scene.item_count(), Some(&nb), true).expect("draw");
        eprintln!("particles {sizes}: {counts:?}");
    }
    group.finish();
}

/// §3.3, §4.4: the stencil pass of the shadow volumes, unclamped and clamped.
fn stencil(c: &mut Criterion) {
    use occult_render::nbuffer::shadows::{Clamping, ShadowCasters, SpotLight};
    let mut group = c.benchmark_group("nbuffer_stencil");
    group.sample_size(10);
    for spec in ["terrain", "city:detail=1"] {
        let (scene, view, frame) = drawn(spec);
        let casters = ShadowCasters::new(scene.clone(), 4096).expect("casters");
        let light = SpotLight::for_bounds(&scene.bounds());
        let mut raster = Rasterizer::new(RasterConfig::default()).expect("valid config");
        for (clamping, mode) in [(Clamping::Off, "unclamped"), (Clamping::On, "clamped")] {
            let volumes = casters
                .volumes(&mut raster, &view, &frame, &light, clamping)
                .expect("volumes");
            let (_, counts) = volumes.stencil(&mut raster, &view, &frame).expect("stencil");
            eprintln!("stencil {spec} {mode}: {counts:?}");
            group.bench_function(format!("{spec}/{mode}"), |b| {
                b.iter(|| volumes.stencil(&mut raster, &view, &frame).expect("stencil"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, build, queries, best, particles, stencil);
criterion_main!(benches);
