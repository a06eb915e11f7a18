//! oqgrid (Hillesland et al. 2002): frames bit-identical to `zbuffer` (DESIGN invariant 2) over
//! every generator with random views (50 per scene for the default, 20 for each other
//! configuration) and over whole camera paths, in every configuration that changes what is
//! queried or drawn; bad parameters are errors.

use std::sync::Arc;

use crate::support::{
    assert_identical_on_path, assert_variant_identical_on_every_generator, build_scene, identical_on_every_generator,
    spec,
};
use occult_core::{Camera, Vec3, View};
use occult_raster::Frame;
use occult_render::{Algorithm, RenderError, RenderOptions};

identical_on_every_generator! {
    nested_default_is_identical_on_every_generator: assert_identical_on_every_generator("oqgrid", 0);
    uniform_batch_1_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:grid=uniform,batch=1,resolution=16", 0);
    uniform_batch_8_fine_grid_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:grid=uniform,batch=8,resolution=40", 2);
    /// Small split threshold and coarse top level: most cells have subgrids (§3.2 recursion).
    nested_deep_small_split_is_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "oqgrid:grid=nested,resolution=3,split=8,branching=2,depth=4,batch=8",
        0
    );
    /// The paper's query alone: no pyramid, no node queries, no whole draws, no visible list.
    paper_query_only_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:test=query,nodes=off,whole=0,coherence=off", 0);
    /// Every mesh drawn whole once any of it was drawn; visible triangles gathered over
    /// batches into large draws (queries meanwhile see a depth without them).
    whole_and_flush_are_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:whole=1,flush=5000", 0);
    /// The pyramid over a uniform grid, gathered draws, two threads.
    pyramid_uniform_flush_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:grid=uniform,resolution=16,flush=300,whole=0", 2);
    /// Strips of columns, each queried against its own depth of them by a worker a thread.
    columns_are_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:parallel=columns", 2);
    /// Three strips a worker, every frame queried, whole draws: a box judged by its strip's
    /// pixels alone.
    columns_without_payoff_are_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:parallel=columns,strips=3,payoff=off,whole=1", 2);
}

#[test]
fn threshold_and_switches_are_identical_on_every_generator() {
    // Cells under 64 triangles drawn unqueried; no stamps (shared triangles drawn per cell);
    // storage order; one thread.
    assert_variant_identical_on_every_generator(&spec("oqgrid:threshold=64,stamps=off,order=none,batch=3"), 1);
    assert_variant_identical_on_every_generator(&spec("oqgrid:queries=off"), 0);
}

#[test]
fn identical_on_paths() {
    for (algo, scene, path) in [
        ("oqgrid", "plant:units=2,floors=2,pipes=10", "street:12"),
        ("oqgrid:grid=uniform,batch=1", "city:blocks=3,detail=3", "street:12"),
        (
            "oqgrid:grid=nested,split=50,resolution=4,batch=8",
            "city:blocks=3,detail=3",
            "flyover:10",
        ),
        (
            "oqgrid:threshold=200,batch=8",
            "forest:trees=3,patches=2,levels=1",
            "circle:10",
        ),
        (
            "oqgrid:grid=nested,split=100,resolution=8",
            "occluder:objects=4",
            "circle:10",
        ),
        // Shares remembered from frame to frame: whole draws, then a probe every 8th frame.
        ("oqgrid:whole=1", "plant:units=2,floors=2,pipes=10", "circle:20"),
        ("oqgrid:whole=100,flush=20000", "city:blocks=3,detail=3", "street:12"),
        (
            "oqgrid:test=query,whole=0,nodes=off",
            "forest:trees=3,patches=2,levels=1",
            "circle:10",
        ),
        // Strips whose columns move from frame to frame, each with its own visible list.
        ("oqgrid:parallel=columns", "city:blocks=3,detail=3", "street:12"),
        (
            "oqgrid:parallel=columns,strips=1,payoff=off",
            "forest:trees=3,patches=2,levels=1",
            "circle:10",
        ),
        (
            "oqgrid:parallel=columns,bands=2",
            "plant:units=2,floors=2,pipes=10",
            "street:12",
        ),
    ] {
        assert_identical_on_path(&spec(algo), scene, path, 160, 120);
    }
}

fn build_err(s: &str) -> String {
    build_err_on("city:blocks=1,detail=1", s)
}

fn build_err_on(scene_spec: &str, s: &str) -> String {
    let scene = Arc::new(build_scene(scene_spec).scene);
    match spec(s).build(scene, &RenderOptions::default()) {
        Err(RenderError::BadParameter(m)) => m,
        Err(e) => panic!("{s}: expected BadParameter, got {e}"),
        Ok(_) => panic!("{s}: accepted"),
    }
}

#[test]
fn bad_parameters_are_clear_errors() {
    for (s, key) in [
        ("oqgrid:resolution=0", "resolution=0"),
        ("oqgrid:resolution=-3", "resolution=-3"),
        ("oqgrid:resolution=lots", "resolution=lots"),
        ("oqgrid:branching=1", "branching=1"),
        ("oqgrid:branching=0", "branching=0"),
        ("oqgrid:threshold=0", "threshold=0"),
        ("oqgrid:batch=0", "batch=0"),
        ("oqgrid:split=0", "split=0"),
        ("oqgrid:depth=99", "depth=99"),
        ("oqgrid:memory=0", "memory=0"),
        ("oqgrid:grid=octree", "grid=octree"),
        ("oqgrid:order=random", "order=random"),
        ("oqgrid:stamps=maybe", "stamps=maybe"),
        ("oqgrid:test=hzb", "test=hzb"),
        ("oqgrid:flush=0", "flush=0"),
        ("oqgrid:whole=101", "whole=101"),
        ("oqgrid:nodes=maybe", "nodes=maybe"),
        ("oqgrid:strips=0", "strips=0"),
        ("oqgrid:strips=17", "strips=17"),
        ("oqgrid:parallel=rows", "parallel=rows"),
    ] {
        let m = build_err(s);
        assert!(
            m.contains("oqgrid") && m.contains(key),
            "{s}: message '{m}' does not name it"
        );
    }
}

#[test]
fn absurd_resolution_is_refused_before_allocating() {
    // 4 billion cells along the longest axis: refused by counting, not by running out of memory.
    let m = build_err("oqgrid:resolution=4000000000");
    assert!(m.contains("resolution=4000000000") && m.contains("at most"), "{m}");
    // A resolution that fits in general, under a memory bound smaller than the grid (a
    // 140,000-triangle plant unit needs more than 1 MiB of cell lists).
    let m = build_err_on("plant:units=1", "oqgrid:resolution=200,memory=1");
    assert!(m.contains("bound"), "{m}");
}

/// The counters add up, and a wall in front of a hidden object culls the object's cells.
#[test]
fn counters_account_for_every_cell() {
    let built = build_scene("occluder:objects=3,tessellation=16");
    let scene = Arc::new(built.scene);
    let opts = RenderOptions::default();
    let view = View::new(built.default_camera, 160, 120).unwrap();
    let mut frame = Frame::new(160, 120).unwrap();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &opts).unwrap();
    let zs = z.render(&view, &mut frame).unwrap();
    let mut r = spec("oqgrid:threshold=1").build(scene.clone(), &opts).unwrap();
    let s = r.render(&view, &mut frame).unwrap();
    let c = |k: &str| s.counters.get(k);
    assert!(c("cells_visited") >= c("cells_in_frustum"));
    assert_eq!(c("cells_in_frustum"), c("queries") + c("queries_skipped"));
    assert_eq!(c("queries") + c("node_queries"), s.boxes_tested);
    assert_eq!(c("queries_hidden") + c("nodes_hidden"), s.boxes_culled);
    assert!(c("pyramid_hidden") <= c("queries_hidden") + c("nodes_hidden"));
    assert!(c("draws") > 0);
    assert_eq!(c("cells_visible"), c("cells_in_frustum") - c("queries_hidden"));
    assert_eq!(c("queries_skipped"), 0, "threshold 1 queries every cell");
    assert!(
        c("queries_hidden") + c("nodes_hidden") > 0,
        "the wall hides the spheres"
    );
    assert!(
        c("pyramid_hidden") > 0,
        "the pyramid alone finds hidden boxes behind the wall"
    );
    assert!(s.triangles_submitted < zs.triangles_submitted);
    assert!(s.phases.get(occult_render::Phase::Query) > std::time::Duration::ZERO);
    // The paper's query alone: the pyramid answers nothing, the same cells are found hidden.
    let mut q = spec("oqgrid:threshold=1,test=query")
        .build(scene.clone(), &opts)
        .unwrap();
    let qs = q.render(&view, &mut frame).unwrap();
    assert_eq!(qs.counters.get("pyramid_hidden"), 0);
    assert_eq!(qs.boxes_culled, s.boxes_culled, "the cheap test changes no answer");
    // A huge threshold skips every query; queries=off issues none.
    for algo in ["oqgrid:threshold=1000000000", "oqgrid:queries=off"] {
        let mut r = spec(algo).build(scene.clone(), &opts).unwrap();
        let s = r.render(&view, &mut frame).unwrap();
        assert_eq!(s.counters.get("queries"), 0, "{algo}");
        assert_eq!(
            s.counters.get("cells_visible"),
            s.counters.get("cells_in_frustum"),
            "{algo}"
        );
    }
}

/// A view from far behind everything, looking away: nothing is queried or drawn.
#[test]
fn view_away_from_the_scene_draws_nothing() {
    let built = build_scene("city:blocks=1,detail=1");
    let scene = Arc::new(built.scene);
    let cam = Camera::look_at(Vec3::new(0.0, 10.0, 5000.0), Vec3::new(0.0, 10.0, 10000.0));
    let view = View::new(cam, 64, 48).unwrap();
    let mut frame = Frame::new(64, 48).unwrap();
    let mut r = spec("oqgrid").build(scene, &RenderOptions::default()).unwrap();
    let s = r.render(&view, &mut frame).unwrap();
    assert_eq!(s.triangles_submitted, 0);
    assert_eq!(s.counters.get("queries"), 0);
    assert_eq!(frame.covered_pixel_count(), 0);
}

/// Batches whose queries cover enough of the screen are evaluated in parallel: frames stay
/// identical (the 96 x 64 views of the other tests are too small to take that path).
#[test]
fn parallel_query_batches_are_identical() {
    let built = build_scene("plant:units=2,floors=2,pipes=10");
    let cams = occult_scenes::path::parse_path("street:6", &built.scene, &built.default_camera).unwrap();
    let scene = Arc::new(built.scene);
    let opts = RenderOptions::default();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &opts).unwrap();
    let mut r = spec("oqgrid:grid=uniform,resolution=2,batch=8,payoff=off")
        .build(scene, &opts)
        .unwrap();
    let (mut a, mut b) = (Frame::new(640, 480).unwrap(), Frame::new(640, 480).unwrap());
    let mut parallel = 0;
    for cam in &cams {
        let view = View::new(*cam, 640, 480).unwrap();
        z.render(&view, &mut a).unwrap();
        let s = r.render(&view, &mut b).unwrap();
        parallel += s.counters.get("parallel_batches");
        assert!(a.same_visibility(&b), "differs from zbuffer: {cam:?}");
    }
    assert!(parallel > 0, "no batch took the parallel path");
}

/// Meshes drawn whole once an earlier frame drew enough of them (and their grids traversed
/// again every 8th frame): frames stay identical, and the whole draws do happen.
#[test]
fn whole_draws_from_earlier_frames_are_identical() {
    let built = build_scene("plant:units=2,floors=2,pipes=10");
    let cams = occult_scenes::path::parse_path("circle:12", &built.scene, &built.default_camera).unwrap();
    let scene = Arc::new(built.scene);
    let opts = RenderOptions::default();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &opts).unwrap();
    let mut r = spec("oqgrid:whole=1,payoff=off").build(scene, &opts).unwrap();
    let (mut a, mut b) = (Frame::new(160, 120).unwrap(), Frame::new(160, 120).unwrap());
    let mut whole = Vec::new();
    for cam in &cams {
        let view = View::new(*cam, 160, 120).unwrap();
        z.render(&view, &mut a).unwrap();
        let s = r.render(&view, &mut b).unwrap();
        whole.push(s.counters.get("whole_drawn"));
        assert!(a.same_visibility(&b), "differs from zbuffer: {cam:?}");
    }
    assert_eq!(whole[0], 0, "nothing is known before the first frame");
    assert!(whole.iter().sum::<u64>() > 0, "no mesh was drawn whole");
}

/// Frame-to-frame coherence (`weigh=off`: whatever the frame times): last frame's visible
/// cells are drawn first, unqueried. Frames stay identical with it on, off and weighed over a
/// path. On a view seen again (without whole draws, whose
/// grids are traversed again now and then), the cells drawn first are all the traversal finds
/// visible (each was visible against less depth before), so the frame draws no more than the
/// first did, all of it from the list.
#[test]
fn coherence_draws_last_frames_cells_first() {
    let built = build_scene("plant:units=2,floors=2,pipes=10");
    let mut cams = occult_scenes::path::parse_path("circle:10", &built.scene, &built.default_camera).unwrap();
    cams.push(cams[9]);
    let scene = Arc::new(built.scene);
    let opts = RenderOptions::default();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &opts).unwrap();
    let mut renderers: Vec<_> = [
        "oqgrid:payoff=off,weigh=off",
        "oqgrid:payoff=off,coherence=off",
        "oqgrid:payoff=off,whole=0,weigh=off",
        // Weighed by frame times: whether the list is drawn depends on the clock, the frames
        // do not.
        "oqgrid:payoff=off",
    ]
    .iter()
    .map(|s| spec(s).build(scene.clone(), &opts).expect("oqgrid builds"))
    .collect();
    let (mut a, mut b) = (Frame::new(160, 120).unwrap(), Frame::new(160, 120).unwrap());
    let mut stats = vec![Vec::new(); renderers.len()];
    for cam in &cams {
        let view = View::new(*cam, 160, 120).unwrap();
        z.render(&view, &mut a).unwrap();
        for (r, s) in renderers.iter_mut().zip(&mut stats) {
            s.push(r.render(&view, &mut b).expect("oqgrid frame"));
            assert!(a.same_visibility(&b), "{} differs from zbuffer: {cam:?}", r.name());
        }
    }
    let coherent = |s: &occult_render::FrameStats| s.counters.get("coherent_cells");
    assert!(stats[1].iter().all(|s| coherent(s) == 0), "off draws nothing first");
    for s in [&stats[0], &stats[2]] {
        assert_eq!(coherent(&s[0]), 0, "nothing is known before the first frame");
        assert!(s[1..].iter().all(|s| coherent(s) > 0));
    }
    let (first, again) = (&stats[2][9], &stats[2][10]);
    assert!(again.triangles_submitted <= first.triangles_submitted);
    assert_eq!(
        again.counters.get("coherent_triangles"),
        again.triangles_submitted,
        "the same view draws only what the list drew"
    );
}
