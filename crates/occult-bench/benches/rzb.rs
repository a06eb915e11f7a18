//! The randomized z-buffer: frame times on a recorded path (chessboard, sampling only and with
//! the large-triangle fallback; forest with sample caching), and dynamic updates of the
//! distribution tree (§5.4: insertion then removal of triangles, per triangle).

mod common;

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use occult_core::{Aabb, Vec3};
use occult_render::RenderOptions;
use occult_spatial::{DistributionTree, SampleOctree, SampleOctreeConfig};
use rand::{Rng, SeedableRng};

fn path_bench(c: &mut Criterion, scene_spec: &str, path: &str, specs: &[&str]) {
    common::bench_path(
        c,
        format!("{scene_spec}_{path}_320x240"),
        scene_spec,
        path,
        (320, 240),
        specs,
    );
}

fn renderers(c: &mut Criterion) {
    path_bench(c, "chessboard:n=1000", "circle:4", &["rzb:large=off", "rzb"]);
    path_bench(c, "forest", "circle:8", &["rzb", "rzb:cache=on"]);
}

/// The cost of a fresh sample through six levels of instancing: one frame of
/// `chessboard:n=10000000` (2·10^14 triangles, 512 unique) from its default camera at
/// 640×480, sampling only (`large=off`), on one thread. The throughput is in samples: its
/// inverse is the cost of a fresh sample with everything a frame adds to it (selection,
/// projection, splat, clear) counted in.
fn fresh_samples(c: &mut Criterion) {
    let w = occult_bench::workload("chessboard:n=10000000");
    let options = RenderOptions {
        raster: occult_raster::RasterConfig {
            threads: 1,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut r = occult_render::AlgoSpec::parse("rzb:large=off")
        .and_then(|s| s.build(Arc::new(w.scene), &options))
        .expect("rzb builds");
    let view = occult_core::View::new(w.camera, 640, 480).expect("a valid view");
    let mut frame = occult_raster::Frame::new(640, 480).expect("a frame");
    let samples = r
        .render(&view, &mut frame)
        .expect("renders")
        .counters
        .get("samples_generated");
    let mut group = c.benchmark_group("rzb_fresh_samples");
    group.sample_size(10);
    group.throughput(Throughput::Elements(samples));
    group.bench_function("chessboard_2e14_six_levels_640x480_1_thread", |b| {
        b.iter(|| r.render(&view, &mut frame).expect("renders"))
    });
    group.finish();
}

/// §5.4 / §8.4: insert 5,804 triangles into a distribution tree built over 1.2 M, then remove
/// them (the paper: 98 µs per triangle).
fn dynamic_updates(c: &mut Criterion) {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
    let n = 1_200_000;
    let extra = 5_804;
    let mut boxes = Vec::with_capacity(n + extra);
    let mut areas = Vec::with_capacity(n + extra);
    for _ in 0..n + extra {
        let p = Vec3::new(
            rng.random::<f32>() * 1000.0,
            rng.random::<f32>() * 20.0,
            rng.random::<f32>() * 1000.0,
        );
        let s = rng.random::<f32>() + 0.1;
        boxes.push(Aabb::new(p, p + Vec3::splat(s)));
        areas.push((s * s) as f64);
    }
    let octree = SampleOctree::build(&boxes[..n], &areas[..n], &vec![0; n], 1, &SampleOctreeConfig::default())
        .expect("default config");
    let mut tree = DistributionTree::from_octree(&octree, &areas[..n], &[]);
    c.bench_function("distribution_tree_insert_remove_5804", |b| {
        b.iter(|| {
            for i in n..n + extra {
                tree.insert(i as u32, boxes[i], areas[i]).expect("insert");
            }
            for i in n..n + extra {
                tree.remove(i as u32).expect("remove");
            }
        })
    });
}

/// §5.4 through the renderer (`dynamic=on`): remove then insert every triangle of the city's
/// largest building mesh (each change also updates every instance of the mesh up the DAG).
fn renderer_updates(c: &mut Criterion) {
    let w = occult_bench::workload("city");
    let scene = Arc::new(w.scene);
    let mesh = (0..scene.nodes().len() as u32)
        .map(occult_core::NodeId)
        .filter(|&n| scene.node(n).mesh().is_some())
        .max_by_key(|&n| scene.node(n).mesh().map_or(0, |m| m.triangle_count()))
        .expect("a mesh");
    let opts = occult_render::rzb::RzbOptions {
        dynamic: true,
        ..Default::default()
    };
    let mut r = occult_render::rzb::Rzb::with_options(scene.clone(), &RenderOptions::default(), &opts).expect("builds");
    let tris: Vec<u32> = (0..scene.node(mesh).mesh().map_or(0, |m| m.triangle_count()) as u32)
        .filter(|&t| r.contains(mesh, t))
        .collect();
    let refs = scene
        .nodes()
        .iter()
        .flat_map(|n| n.instances())
        .filter(|i| i.child == mesh)
        .count();
    c.bench_function(
        &format!("rzb_remove_insert_{}_triangles_{}_instances", tris.len(), refs),
        |b| {
            b.iter(|| {
                for &t in &tris {
                    r.remove(mesh, t).expect("remove");
                }
                for &t in &tris {
                    r.insert(mesh, t).expect("insert");
                }
            })
        },
    );
}

criterion_group!(benches, fresh_samples, renderers, dynamic_updates, renderer_updates);
criterion_main!(benches);
