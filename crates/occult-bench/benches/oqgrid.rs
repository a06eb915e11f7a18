//! oqgrid frame times on recorded street paths of `plant` and `city` (640 × 480), beside
//! `frustum`, in the configurations the README reports: uniform and nested grids, batch 1 and
//! 8, queries off (§4.2's throughput baseline). One iteration renders the whole path. Also the
//! cost of one occlusion query of a mid-sized box against a drawn frame.

mod common;

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use occult_core::{Aabb, Affine3A, View};
use occult_raster::Frame;
use occult_render::oqgrid::any_sample_passes;
use occult_render::{Algorithm, RenderOptions};

fn paths(c: &mut Criterion) {
    for scene_spec in ["plant", "city"] {
        let specs = [
            "frustum",
            "oqgrid:grid=uniform,batch=1",
            "oqgrid:grid=uniform,batch=8",
            "oqgrid:grid=nested,resolution=8,split=1000",
            "oqgrid:queries=off",
        ];
        let group = format!("oqgrid_{scene_spec}_street8_640x480");
        common::bench_path(c, group, scene_spec, "street:8", (640, 480), &specs);
    }
}

fn query(c: &mut Criterion) {
    let w = occult_bench::workload("city");
    let view = View::new(w.camera, 640, 480).expect("valid view");
    let scene = Arc::new(w.scene);
    let mut frame = Frame::new(640, 480).expect("valid size");
    Algorithm::ZBUFFER
        .build(scene.clone(), &RenderOptions::default())
        .expect("zbuffer builds")
        .render(&view, &mut frame)
        .expect("render");
    let clip = view.clip_from_object(&Affine3A::IDENTITY);
    // A building-sized box behind the first row of the street: mostly hidden.
    let hidden = Aabb::new(
        occult_core::Vec3::new(-10.0, 0.0, 40.0),
        occult_core::Vec3::new(10.0, 20.0, 60.0),
    );
    c.bench_function("oqgrid_query_box_city", |b| {
        b.iter(|| any_sample_passes(&frame, &view, &clip, std::hint::black_box(&hidden)))
    });
    c.bench_function("raster_query_box_city", |b| {
        b.iter(|| occult_raster::query_box(&frame, &view, &clip, std::hint::black_box(&hidden)))
    });
}

criterion_group!(benches, paths, query);
criterion_main!(benches);
