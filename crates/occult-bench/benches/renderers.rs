//! Frame times of the renderers on recorded camera paths: `zbuffer` and `frustum` on `city`
//! (street views, where culling must pay off). One iteration renders the whole path.

mod common;

use criterion::{criterion_group, criterion_main, Criterion};

fn city(c: &mut Criterion) {
    common::bench_path(
        c,
        "city_street8_640x480".into(),
        "city",
        "street:8",
        (640, 480),
        &["zbuffer", "frustum"],
    );
}

criterion_group!(benches, city);
criterion_main!(benches);
