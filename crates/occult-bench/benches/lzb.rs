//! Local z-buffering (`lzb`): the ray caster's throughput on `terrain` (first-hit rays through
//! the octree, one thread, every pixel cast: `mode=naive,plane=static,plane_fraction=0.0001,
//! oor=off`), printed as rays per second per thread beside criterion's frame time; and `lzb`
//! frames on `city` along a circle, beside `zbuffer`.

mod common;

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use occult_core::View;
use occult_raster::{Frame, RasterConfig};
use occult_render::{AlgoSpec, Phase, RenderOptions};

fn one_thread() -> RenderOptions {
    RenderOptions {
        raster: RasterConfig {
            threads: 1,
            ..RasterConfig::default()
        },
    }
}

fn terrain_rays(c: &mut Criterion) {
    let w = occult_bench::workload("terrain");
    let view = View::new(w.camera, 640, 360).expect("valid view");
    let scene = Arc::new(w.scene);
    let spec = AlgoSpec::parse("lzb:mode=naive,plane=static,plane_fraction=0.0001,oor=off").expect("valid spec");
    let mut r = spec.build(scene, &one_thread()).expect("renderer builds");
    let mut frame = Frame::new(640, 360).expect("valid size");
    let (mut rays, mut secs) = (0u64, 0f64);
    let mut group = c.benchmark_group("lzb_terrain_640x360");
    group.sample_size(10);
    group.bench_function("naive_rays_1_thread", |b| {
        b.iter(|| {
            let s = r.render(&view, &mut frame).expect("render");
            rays += s.rays_cast;
            secs += s.phases.get(Phase::Rays).as_secs_f64();
        })
    });
    group.finish();
    eprintln!(
        "lzb ray caster on terrain: {:.2} Mrays/s per thread ({rays} rays in {secs:.3} s of the rays phase)",
        rays as f64 / secs / 1e6
    );
}

fn city_circle(c: &mut Criterion) {
    common::bench_path(
        c,
        "city_circle8_512x512".into(),
        "city",
        "circle:8",
        (512, 512),
        // The paper's algorithm alone: with payoff, frames it loses are drawn as frustum does.
        &["zbuffer", "lzb:payoff=off"],
    );
}

criterion_group!(benches, terrain_rays, city_circle);
criterion_main!(benches);
