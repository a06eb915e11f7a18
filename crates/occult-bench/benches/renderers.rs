//! Frame times of the renderers on recorded camera paths: `zbuffer` and `frustum` on `city`
//! (street views, where culling must pay off). One iteration renders the whole path.

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use occult_core::View;
use occult_raster::Frame;
use occult_render::{Algorithm, RenderOptions};

fn city(c: &mut Criterion) {
    let w = occult_bench::workload("city");
    let cameras = occult_scenes::path::parse_path("street:8", &w.scene, &w.camera).expect("street path on city");
    let views: Vec<View> = cameras
        .iter()
        .map(|c| View::new(*c, 640, 480).expect("valid view"))
        .collect();
    let scene = Arc::new(w.scene);
    let mut group = c.benchmark_group("city_street8_640x480");
    group.sample_size(10);
    for algo in [Algorithm::ZBUFFER, Algorithm::FRUSTUM] {
        let mut r = algo
            .build(scene.clone(), &RenderOptions::default())
            .expect("renderer builds");
        let mut frame = Frame::new(640, 480).expect("valid size");
        group.bench_function(algo.name(), |b| {
            b.iter(|| {
                for v in &views {
                    r.render(v, &mut frame).expect("render");
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, city);
criterion_main!(benches);
