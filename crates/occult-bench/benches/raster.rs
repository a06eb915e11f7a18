//! Rasterizer throughput: the `terrain` anchor view (1 and 2 threads, exact depth and item
//! ids) and random triangles of three sizes. Times are for one `Rasterizer::draw` of all the
//! triangles into a frame cleared before each (the clear is not timed; `clear` benchmarks it).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occult_core::glam::Affine3A;
use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer};

fn draw_all(c: &mut Criterion, name: &str, mesh: &occult_core::Mesh, view: &occult_core::View, threads: usize) {
    let mut raster = Rasterizer::new(RasterConfig {
        threads,
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
    let mut group = c.benchmark_group("raster");
    group.throughput(Throughput::Elements(mesh.triangle_count() as u64));
    group.sample_size(20);
    group.bench_function(format!("{name}/threads={threads}/{}", raster.isa_name()), |b| {
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

criterion_group!(benches, terrain, clear, random);
criterion_main!(benches);
