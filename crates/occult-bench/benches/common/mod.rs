//! The loop shared by the benchmarks that replay a camera path: one renderer object per spec,
//! built before timing, and one iteration rendering every view of the path.

use std::sync::Arc;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion};
use occult_core::{Scene, View};
use occult_raster::Frame;
use occult_render::{AlgoSpec, RenderOptions};

/// Adds one benchmark per spec of `specs` to `group`, named by its label: every view of `views`
/// (one frame size, that of the first) rendered in order by one renderer object built on
/// `scene` with default options, so that state kept across frames carries over.
///
/// # Panics
/// If a spec does not parse or build, or a frame cannot be made: benchmarks use fixed,
/// known-good specs.
pub fn bench_specs(group: &mut BenchmarkGroup<'_, WallTime>, scene: &Arc<Scene>, views: &[View], specs: &[&str]) {
    let (width, height) = views.first().map_or((1, 1), |v| (v.width(), v.height()));
    for s in specs {
        let spec = AlgoSpec::parse(s).expect("valid spec");
        let mut r = spec
            .build(scene.clone(), &RenderOptions::default())
            .expect("renderer builds");
        let mut frame = Frame::new(width, height).expect("valid size");
        group.bench_function(spec.label(), |b| {
            b.iter(|| {
                for v in views {
                    r.render(v, &mut frame).expect("render");
                }
            })
        });
    }
}

/// The benchmark group `group_name` (10 samples) of [`bench_specs`] over every view of camera
/// path `path` on the workload `scene_spec` (see [`occult_bench::path_views`]) at
/// `width × height`.
///
/// # Panics
/// As [`bench_specs`], and if the workload or the path does not build.
pub fn bench_path(
    c: &mut Criterion,
    group_name: String,
    scene_spec: &str,
    path: &str,
    (width, height): (u32, u32),
    specs: &[&str],
) {
    let (scene, views) = occult_bench::path_views(scene_spec, path, width, height);
    let mut group = c.benchmark_group(group_name);
    group.sample_size(10);
    bench_specs(&mut group, &scene, &views, specs);
    group.finish();
}
