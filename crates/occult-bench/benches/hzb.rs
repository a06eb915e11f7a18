//! Frame times of `hzb` against `zbuffer` and `frustum` on recorded camera paths (`city`
//! street views and `plant`), and of its ablations (each part switched off). One iteration
//! renders the whole path with one renderer object, so the visible list carries over.

mod common;

use criterion::{criterion_group, criterion_main, Criterion};

fn path_bench(c: &mut Criterion, scene_spec: &str, path: &str, specs: &[&str]) {
    let group = format!("hzb_{scene_spec}_{path}_640x480").replace([':', ','], "_");
    common::bench_path(c, group, scene_spec, path, (640, 480), specs);
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
