//! Frame times of `hzb` against `zbuffer` and `frustum` on recorded camera paths (`city`
//! street views and `plant`), and of its ablations (each part switched off). One iteration
//! renders the whole path with one renderer object, so the visible list carries over.

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use occult_core::View;
use occult_raster::Frame;
use occult_render::{AlgoSpec, RenderOptions};

fn path_bench(c: &mut Criterion, scene_spec: &str, path: &str, specs: &[&str]) {
    let w = occult_bench::workload(scene_spec);
    let cameras = occult_scenes::path::parse_path(path, &w.scene, &w.camera).expect("path on the scene");
    let views: Vec<View> = cameras
        .iter()
        .map(|c| View::new(*c, 640, 480).expect("valid view"))
        .collect();
    let scene = Arc::new(w.scene);
    let mut group = c.benchmark_group(format!("hzb_{scene_spec}_{path}_640x480").replace([':', ','], "_"));
    group.sample_size(10);
    for s in specs {
        let spec = AlgoSpec::parse(s).expect("valid spec");
        let mut r = spec
            .build(scene.clone(), &RenderOptions::default())
            .expect("renderer builds");
        let mut frame = Frame::new(640, 480).expect("valid size");
        group.bench_function(spec.label(), |b| {
            b.iter(|| {
                for v in &views {
                    r.render(v, &mut frame).expect("render");
                }
            })
        });
    }
    group.finish();
}

fn city(c: &mut Criterion) {
    path_bench(
        c,
        "city",
        "street:8",
        &[
            "zbuffer",
            "frustum",
            "hzb",
            "hzb:temporal=off",
            "hzb:pyramid=off",
            "hzb:occlusion=off",
            "hzb:parallel=hybrid",
        ],
    );
}

fn plant(c: &mut Criterion) {
    path_bench(
        c,
        "plant",
        "circle:8",
        &["zbuffer", "frustum", "hzb", "hzb:temporal=off"],
    );
}

criterion_group!(benches, city, plant);
criterion_main!(benches);
