//! Frame times of the renderers on recorded camera paths: `zbuffer` and `frustum` on `city`
//! (street views, where culling must pay off). One iteration renders the whole path.

mod common;

use criterion::{criterion_group, criterion_main, Criterion};

fn city(c: &mut Criterion) {
    let (scene, views) = occult_bench::path_views("city", "street:8", 640, 480);
    let mut group = c.benchmark_group("city_street8_640x480");
    group.sample_size(10);
    common::bench_specs(&mut group, &scene, &views, &["zbuffer", "frustum"]);
    group.finish();
}

criterion_group!(benches, city);
criterion_main!(benches);
