//! The loop shared by the benchmarks that replay a camera path: one renderer object per spec,
//! built before timing, and one iteration rendering every view of the path.

use std::sync::Arc;

use criterion::measurement::WallTime;
use criterion::BenchmarkGroup;
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
