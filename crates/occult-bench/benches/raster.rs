//! Rasterizer throughput: the `terrain` anchor view (1 and 2 threads, exact depth and item
//! ids), the same mesh from behind (projection and outcode rejection only), random triangles
//! of three sizes, and the two-thread strategies forced on random triangles. Times are for one
//! `Rasterizer::draw` of all the triangles into a frame cleared before each (the clear is not
//! timed; `clear` benchmarks it).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occult_core::glam::Affine3A;
use occult_core::{Camera, Vec3, View};
use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer, Strategy};

fn draw_all(c: &mut Criterion, name: &str, mesh: &occult_core::Mesh, view: &occult_core::View, threads: usize) {
    draw_with(c, name, mesh, view, threads, Strategy::Auto);
}

/// One draw of `mesh` per iteration, the frame cleared (untimed) before each, named
/// `{name}/threads={threads}/{isa}` under the automatic strategy and
/// `{name}/threads={threads}/{strategy}` under a forced one.
fn draw_with(
    c: &mut Criterion,
    name: &str,
    mesh: &occult_core::Mesh,
    view: &occult_core::View,
    threads: usize,
    strategy: Strategy,
) {
    let mut raster = Rasterizer::new(RasterConfig {
        threads,
        strategy,
        ..RasterConfig::default()
    })
    .expect("valid config");
    let mut frame = Frame::new(view.width(), view.height()).expect("valid size");
    let draw = Draw {
        mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let label = match strategy {
        Strategy::Auto => format!("{name}/threads={threads}/{}", raster.isa_name()),
        s => format!("{name}/threads={threads}/{s:?}"),
    };
    let mut group = c.benchmark_group("raster");
    group.throughput(Throughput::Elements(mesh.triangle_count() as u64));
    group.sample_size(20);
    group.bench_function(label, |b| {
        b.iter_custom(|iterations| {
            let mut total = std::time::Duration::ZERO;
            for _ in 0..iterations {
                raster.clear(&mut frame);
                let start = std::time::Instant::now();
                std::hint::black_box(raster.draw(view, &mut frame, std::slice::from_ref(&draw), RasterMode::Full));
                total += start.elapsed();
            }
            total
        })
    });
    group.finish();
}

fn terrain(c: &mut Criterion) {
    let (scene, view) = occult_bench::terrain_view();
    let mesh = scene
        .node(scene.root())
        .mesh()
        .expect("terrain is one mesh at g=724, tiles=1");
    for threads in [1, 2] {
        draw_all(c, "terrain", mesh, &view, threads);
    }
    // The same mesh from its default eye looking away from it: every triangle is rejected by
    // its corners' outcodes, so the draw measures vertex projection and the reject loop.
    let camera = Camera::look_at(Vec3::new(0.0, 25.0, -110.0), Vec3::new(0.0, 25.0, -300.0));
    let behind = View::new(camera, view.width(), view.height()).expect("a valid camera");
    draw_all(c, "terrain_behind", mesh, &behind, 1);
}

fn clear(c: &mut Criterion) {
    let mut group = c.benchmark_group("raster");
    for threads in [1, 2] {
        let raster = Rasterizer::new(RasterConfig {
            threads,
            ..RasterConfig::default()
        })
        .expect("valid config");
        let mut frame = Frame::new(1920, 1080).expect("valid size");
        group.bench_function(format!("clear_1920x1080/threads={threads}"), |b| {
            b.iter(|| raster.clear(&mut frame))
        });
    }
    group.finish();
}

/// Large and medium random triangles on two threads, drawn directly, by bands and sort-last
/// (the strategies forced): what sharing the fill and sharing the setup each gain.
fn strategies(c: &mut Criterion) {
    for (name, count, size) in [("large_300px", 200, 300.0), ("medium_10px", 2000, 10.0)] {
        let (mesh, view) = occult_bench::random_triangles(count, size, 1);
        for s in [Strategy::Direct, Strategy::Banded, Strategy::SortLast] {
            draw_with(c, name, &mesh, &view, 2, s);
        }
    }
}

fn random(c: &mut Criterion) {
    for (name, count, size) in [
        ("small_1px", 200_000, 1.0),
        ("medium_10px", 50_000, 10.0),
        ("large_300px", 200, 300.0),
    ] {
        let (mesh, view) = occult_bench::random_triangles(count, size, 1);
        draw_all(c, name, &mesh, &view, 1);
    }
}

/// The draw form of the culling renderers: the `city` overview (`circle` view 0, 1280 × 720)
/// drawn as whole meshes (one `All` draw per instance) and as the same triangles in index
/// lists of 64 consecutive triangles (an octree leaf's worth), handed over in batches of
/// about 4096 triangles as hzb does. Throughput counts the triangles submitted.
fn small_draws(c: &mut Criterion) {
    let w = occult_bench::workload("city");
    let camera = occult_scenes::path::parse_path("circle:1", &w.scene, &w.camera).expect("valid path")[0];
    let view = occult_core::View::new(camera, 1280, 720).expect("valid view");
    let mut whole = Vec::new();
    let mut instances = Vec::new();
    w.scene.for_each_mesh_instance(|world, _, mesh, first| {
        let clip = view.clip_from_object(world);
        whole.push(Draw {
            mesh,
            triangles: DrawTriangles::All,
            clip_from_object: clip,
            first_item: first,
        });
        instances.push((mesh, clip, first));
    });
    let lists: Vec<Vec<u32>> = instances
        .iter()
        .map(|(m, _, _)| (0..m.triangle_count() as u32).collect())
        .collect();
    let mut batches: Vec<Vec<Draw<'_>>> = vec![Vec::new()];
    let mut in_batch = 0;
    for ((mesh, clip, first), list) in instances.iter().zip(&lists) {
        for part in list.chunks(64) {
            batches.last_mut().expect("one batch").push(Draw {
                mesh,
                triangles: DrawTriangles::List(part),
                clip_from_object: *clip,
                first_item: *first,
            });
            in_batch += part.len();
            if in_batch >= 4096 {
                batches.push(Vec::new());
                in_batch = 0;
            }
        }
    }
    let total: u64 = whole.iter().map(|d| d.mesh.triangle_count() as u64).sum();
    let mut frame = Frame::new(1280, 720).expect("valid size");
    let mut group = c.benchmark_group("raster/city_overview");
    group.throughput(Throughput::Elements(total));
    group.sample_size(10);
    for threads in [1, 2] {
        let mut raster = Rasterizer::new(RasterConfig {
            threads,
            ..RasterConfig::default()
        })
        .expect("valid config");
        for (form, sets) in [("whole", vec![whole.clone()]), ("lists64", batches.clone())] {
            group.bench_function(format!("{form}/threads={threads}"), |b| {
                b.iter_custom(|iterations| {
                    let mut time = std::time::Duration::ZERO;
                    for _ in 0..iterations {
                        raster.clear(&mut frame);
                        let start = std::time::Instant::now();
                        for draws in &sets {
                            std::hint::black_box(raster.draw(&view, &mut frame, draws, RasterMode::Full));
                        }
                        time += start.elapsed();
                    }
                    time
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, terrain, clear, random, small_draws, strategies);
criterion_main!(benches);
