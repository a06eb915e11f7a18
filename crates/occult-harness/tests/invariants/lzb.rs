//! `lzb` (local z-buffering, Han & Zeiger) against `zbuffer`: every conservative configuration
//! bit-identical over every generator (50 random views for the default, 20 for each other
//! configuration) and over whole camera paths, and on the cases where rays and the rasterizer
//! disagree (pixel centres on shared edges, coplanar and near-coplanar triangles); the naive
//! ray-casting mode measured, not held identical; bad parameters refused.

use std::sync::Arc;

use crate::support::{assert_identical_on_path, identical_on_every_generator, spec};
use occult_core::{Affine3A, Camera, Instance, Mesh, Scene, SceneBuilder, Vec3, View};
use occult_raster::Frame;
use occult_render::{Algorithm, RenderError, RenderOptions, Renderer};

identical_on_every_generator! {
    default_is_identical_on_every_generator: assert_identical_on_every_generator("lzb", 1);
    /// The algorithm alone (its default PVL, `pvl=hits`): with payoff, frames it loses are
    /// drawn directly instead, so every other configuration here turns it off too.
    without_payoff_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off", 1);
    /// The paper's octree, whose leaves on the rays' paths make the PVL.
    paper_octree_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,caster=octree", 1);
    lazy_all_triangles_static_plane_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,select=all,plane=static,plane_fraction=0.15,oor=off,caster=octree", 2);
    static_occluders_small_leaves_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,select=static,k=1,leaf=8,depth=6,coherence=off,caster=octree", 0);
    dynamic_selection_every_frame_plane_is_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "lzb:payoff=off,select=dynamic,base_cos=0.9,plane_reuse=1,coarse_rays=16,group_leaf=1,caster=octree",
        1
    );
    /// A plane halfway: the far leaves of instances hidden behind the near set are dropped
    /// before the rays (`far_cull=on`, the default), with the paper's near pass.
    far_cull_plane_halfway_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,plane=static,plane_fraction=0.5,near_cull=off,far_cull=on", 2);
    /// The near pass without last frame's visible leaves first.
    near_cull_without_temporal_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,near_temporal=off", 1);
    /// A tiny plane: almost nothing near, almost every pixel goes to the rays.
    hybrid_everything_behind_the_plane_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,plane=static,plane_fraction=0.0001,leaf=32", 2);
    /// Rays record triangles, not leaves; almost every pixel goes to the rays.
    triangle_pvl_everything_behind_the_plane_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,pvl=triangles,plane=static,plane_fraction=0.0001", 1);
    /// The BVH as the rays' structure with its leaves as the PVL (the paper's octree's, with
    /// `caster=octree`); then almost every pixel goes to the rays.
    bvh_caster_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,caster=bvh,pvl=leaves", 1);
    bvh_caster_everything_behind_the_plane_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,caster=bvh,plane=static,plane_fraction=0.0001,pvl=leaves", 2);
    bvh_caster_dynamic_selection_is_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "lzb:payoff=off,caster=bvh,select=dynamic,base_cos=0.9,plane_reuse=1,coarse_rays=16,group_leaf=1,pvl=leaves",
        1
    );
    /// BVH leaves of one and of eight triangles, everything to the rays.
    bvh_leaf_sizes_are_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "lzb:payoff=off,caster=bvh,bvh_leaf=1,plane=static,plane_fraction=0.0001,select=all,pvl=leaves",
        0
    );
    bvh_large_leaves_are_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "lzb:payoff=off,caster=bvh,bvh_leaf=8,plane=static,plane_fraction=0.0001,pvl=triangles",
        1
    );
    /// The triangles the rays' cones may touch, cast in packets (`pvl=hits`, the default; with
    /// the cost plane above): with the paper's mean-hit plane and near pass, then with
    /// everything to the rays, every unfinished pixel cast, and with leaves of one triangle and
    /// group octrees of one instance a leaf (the packets' enclosing cone at its tightest).
    hit_pvl_dynamic_plane_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,pvl=hits,plane=dynamic,near_cull=off", 1);
    hit_pvl_everything_behind_the_plane_is_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "lzb:payoff=off,pvl=hits,plane=static,plane_fraction=0.0001,oor=off",
        2
    );
    hit_pvl_small_leaves_is_identical_on_every_generator: assert_variant_identical_on_every_generator(
        "lzb:payoff=off,pvl=hits,bvh_leaf=1,group_leaf=1,plane=static,plane_fraction=0.0001",
        0
    );
    /// Octree leaves as large as `leaf=auto` makes them on scenes of tens of millions of
    /// triangles: the generators' meshes (up to a few thousand triangles) then hold one leaf
    /// each or a few large ones; with the cost plane, and with the plane halfway.
    large_leaves_are_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,leaf=4000", 1);
    large_leaves_plane_halfway_are_identical_on_every_generator:
        assert_variant_identical_on_every_generator("lzb:payoff=off,leaf=600,plane=static,plane_fraction=0.5", 2);
}

#[test]
fn identical_on_paths() {
    for algo in [
        "lzb",
        "lzb:caster=octree",
        "lzb:payoff=off,select=all,oor=off,caster=octree",
        "lzb:payoff=off,plane=static,plane_fraction=0.3,select=static,caster=octree",
        "lzb:payoff=off,caster=bvh,plane=static,plane_fraction=0.3,pvl=leaves",
        "lzb:payoff=off,caster=bvh,select=all,oor=off,pvl=leaves",
        // Everything near: the near pass alone, last frame's visible leaves first.
        "lzb:payoff=off,plane=static,plane_fraction=1",
    ] {
        assert_identical_on_path(&spec(algo), "city:blocks=3,detail=1", "circle:12", 128, 96);
        assert_identical_on_path(&spec(algo), "forest:trees=2,patches=2", "flyover:8", 96, 64);
        assert_identical_on_path(
            &spec(algo),
            "plant:units=1,floors=2,pipes=8,sides=6",
            "street:8",
            96,
            64,
        );
    }
}

/// A camera looking down `-z` at the plane `z = 0` from `z = 10`, 96×64 pixels, and the world
/// size of one pixel on that plane.
fn straight_view() -> (View, f32) {
    let cam = Camera {
        near: 0.5,
        far: 100.0,
        ..Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO)
    };
    let px = 2.0 * 10.0 * (30f32).to_radians().tan() / 64.0;
    (View::new(cam, 96, 64).unwrap(), px)
}

/// A grid of `n × n` quads (2 triangles each) on `z = z`, whose vertices project exactly onto
/// pixel centres (every pixel centre on a row or column of vertices lies on a shared edge), the
/// diagonals through pixel centres too.
fn edge_grid(n: u32, px: f32, z: f32, offset: Vec3) -> Mesh {
    let mut p = Vec::new();
    let mut t = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            // Pixel centres lie at half-pixel positions from the centre of an even-sized view.
            let x = (i as f32 - n as f32 / 2.0 + 0.5) * px * 2.0;
            let y = (j as f32 - n as f32 / 2.0 + 0.5) * px * 2.0;
            p.push(Vec3::new(x, y, z) + offset);
        }
    }
    let w = n + 1;
    for j in 0..n {
        for i in 0..n {
            let a = j * w + i;
            t.push([a, a + 1, a + w + 1]);
            t.push([a, a + w + 1, a + w]);
        }
    }
    Mesh::new(p, t).unwrap()
}

fn check_scene(scene: Scene, views: &[View], algos: &[&str]) {
    let scene = Arc::new(scene);
    let mut rays = 0;
    let o = RenderOptions::default();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &o).unwrap();
    for algo in algos {
        let mut r = spec(algo).build(scene.clone(), &o).unwrap();
        for (k, view) in views.iter().enumerate() {
            let (mut a, mut b) = (
                Frame::new(view.width(), view.height()).unwrap(),
                Frame::new(view.width(), view.height()).unwrap(),
            );
            z.render(view, &mut a).unwrap();
            let stats = r.render(view, &mut b).unwrap();
            assert!(a.covered_pixel_count() > 0);
            assert!(
                a.same_visibility(&b),
                "{algo}, view {k}: {} pixels differ",
                a.differing_item_count(&b)
            );
            rays += stats.rays_cast;
        }
    }
    // The cases are about rays: they must have been cast.
    assert!(rays > 0);
}

/// Configurations that send (nearly) everything to the rays.
const RAY_HEAVY: &[&str] = &[
    "lzb:payoff=off,plane=static,plane_fraction=0.0001",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,select=all,oor=off,leaf=1,depth=8,caster=octree",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,select=static,k=1,leaf=4,caster=octree",
    "lzb:payoff=off,plane=dynamic,select=dynamic,base_cos=1,leaf=2,caster=octree",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,pvl=triangles,select=all",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,caster=bvh,pvl=leaves",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,select=static,k=1,caster=bvh,pvl=leaves",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,select=all,caster=bvh,bvh_leaf=1,pvl=leaves",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,caster=bvh,bvh_leaf=8,coherence=off,pvl=leaves",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,pvl=hits",
    "lzb:payoff=off,plane=static,plane_fraction=0.0001,pvl=hits,bvh_leaf=1,oor=off",
];

#[test]
fn pixel_centres_on_shared_edges() {
    let (view, px) = straight_view();
    let mut b = SceneBuilder::new();
    // Front layer with holes (every other quad removed), a full layer behind it.
    let front = edge_grid(20, px, 1.0 - 1e-3, Vec3::ZERO);
    let tris: Vec<[u32; 3]> = front
        .triangles()
        .iter()
        .enumerate()
        .filter(|(i, _)| (i / 2) % 3 != 1)
        .map(|(_, t)| *t)
        .collect();
    let front = Mesh::new(front.positions().to_vec(), tris).unwrap();
    let back = edge_grid(24, px, 0.0, Vec3::ZERO);
    let f = b.add_mesh("front", front).unwrap();
    let k = b.add_mesh("back", back).unwrap();
    let root = b
        .add_group(
            "both",
            vec![
                Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child: f,
                },
                Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child: k,
                },
            ],
        )
        .unwrap();
    // Views shifted by fractions of a pixel, so centres fall on, next to, and between edges.
    let views: Vec<View> = [0.0, 0.5, 0.25, 1e-4]
        .iter()
        .map(|&s| {
            let mut c = *view.camera();
            c.eye.x += s * px;
            c.target.x += s * px;
            View::new(c, 96, 64).unwrap()
        })
        .collect();
    check_scene(b.build(root).unwrap(), &views, RAY_HEAVY);
}

#[test]
fn coplanar_and_near_coplanar_layers() {
    let (view, px) = straight_view();
    let mut b = SceneBuilder::new();
    let grid = b.add_mesh("grid", edge_grid(16, px * 1.37, 0.0, Vec3::ZERO)).unwrap();
    // The same grid three times: exactly coplanar (ties broken by item id), and shifted by a
    // depth below the rays' resolution, in front and behind, and slid sideways by a fraction
    // of a pixel (edges crossing).
    let place = |t: Vec3| Instance {
        parent_from_child: Affine3A::from_translation(t),
        child: grid,
    };
    let root = b
        .add_group(
            "layers",
            vec![
                place(Vec3::ZERO),
                place(Vec3::ZERO),
                place(Vec3::new(0.0, 0.0, 1e-6)),
                place(Vec3::new(0.0, 0.0, -1e-6)),
                place(Vec3::new(px * 0.3, px * 0.1, 2e-6)),
            ],
        )
        .unwrap();
    let mut tilted = *view.camera();
    tilted.eye = Vec3::new(3.0, -2.0, 9.0);
    let views = [view, View::new(tilted, 96, 64).unwrap()];
    check_scene(b.build(root).unwrap(), &views, RAY_HEAVY);
}

#[test]
fn naive_mode_is_approximate_and_measured() {
    let built = occult_scenes::spec::parse_spec("city:blocks=2,detail=2")
        .unwrap()
        .build()
        .unwrap();
    let scene = Arc::new(built.scene);
    let o = RenderOptions::default();
    let mut z = Algorithm::ZBUFFER.build(scene.clone(), &o).unwrap();
    let mut r = spec("lzb:mode=naive").build(scene.clone(), &o).unwrap();
    assert!(!r.is_conservative());
    assert!(spec("lzb").build(scene.clone(), &o).unwrap().is_conservative());
    let view = View::new(built.default_camera, 128, 96).unwrap();
    let (mut a, mut b) = (Frame::new(128, 96).unwrap(), Frame::new(128, 96).unwrap());
    z.render(&view, &mut a).unwrap();
    let stats = r.render(&view, &mut b).unwrap();
    assert!(stats.rays_cast > 0);
    let differing = a.differing_item_count(&b);
    // First hits name the right triangle almost everywhere (edges and depth rounding aside).
    assert!(
        differing * 20 < a.covered_pixel_count(),
        "{differing} of {} pixels",
        a.covered_pixel_count()
    );
}

/// Naive rays cast in packets (the default with the BVH) find the hits they find one at a
/// time, through meshes, groups (also of one instance a leaf) and nested instances, from
/// random views and with two threads:
/// the same item and depth at every pixel, but where a hit ties the nearest to within rounding
/// (a traversal may skip the leaf of a hit that rounds a few units in the last place nearer
/// than the leaf's box; the two orders skip differently).
#[test]
fn naive_packets_find_the_single_rays_hits() {
    let mut rng = <rand_pcg::Pcg64Mcg as rand::SeedableRng>::seed_from_u64(23);
    let (mut covered, mut differing) = (0u64, 0u64);
    for threads in [1, 2] {
        let o = RenderOptions {
            raster: occult_raster::RasterConfig {
                threads,
                ..Default::default()
            },
            ..Default::default()
        };
        for scene_spec in crate::support::SCENES {
            let scene = Arc::new(
                occult_scenes::spec::parse_spec(scene_spec)
                    .unwrap()
                    .build()
                    .unwrap()
                    .scene,
            );
            // With two threads, group octrees of one instance a leaf: the packets' cone must
            // find each leaf a ray enters.
            // and naive mode's own plane and object-oriented rays: the cast pixels have holes, so
            // packets are not whole tiles.
            let rays = [
                "lzb:mode=naive,plane=static,plane_fraction=0.0001,oor=off",
                "lzb:mode=naive,group_leaf=1",
            ][threads - 1];
            let mut packets = spec(rays).build(scene.clone(), &o).unwrap();
            let mut single = spec(&format!("{rays},packets=off")).build(scene.clone(), &o).unwrap();
            for _ in 0..6 {
                // Not whole tiles at the right and bottom edges.
                let view = View::new(*crate::support::random_view(&mut rng, &scene).camera(), 97, 61).unwrap();
                let (mut a, mut b) = (Frame::new(97, 61).unwrap(), Frame::new(97, 61).unwrap());
                let sa = packets.render(&view, &mut a).unwrap();
                let sb = single.render(&view, &mut b).unwrap();
                assert_eq!(sa.rays_cast, sb.rays_cast, "{scene_spec}");
                assert_eq!(a.covered_pixel_count(), b.covered_pixel_count(), "{scene_spec}");
                let d = a.differing_item_count(&b);
                for (p, q) in a.depth().iter().zip(b.depth()) {
                    assert!(
                        (p - q).abs() <= 1e-5 * p.abs().max(q.abs()),
                        "{scene_spec}: depth {p} against {q}"
                    );
                }
                covered += a.covered_pixel_count();
                differing += d;
            }
        }
    }
    assert!(covered > 50_000, "{covered}");
    assert!(differing * 1000 <= covered, "{differing} of {covered} pixels differ");
}

#[test]
fn bad_parameters_are_errors() {
    let scene = Arc::new(
        occult_scenes::spec::parse_spec("terrain:g=8")
            .unwrap()
            .build()
            .unwrap()
            .scene,
    );
    let o = RenderOptions::default();
    for (bad, names) in [
        ("lzb:leaf=0", "leaf"),
        ("lzb:k=0,caster=octree", "k"),
        ("lzb:plane_fraction=0", "plane_fraction"),
        ("lzb:plane_fraction=1.5", "plane_fraction"),
        ("lzb:plane_fraction=-0.2", "plane_fraction"),
        ("lzb:coarse_rays=0", "coarse_rays"),
        ("lzb:depth=25", "depth"),
        ("lzb:group_leaf=0", "group_leaf"),
        ("lzb:base_cos=2,caster=octree", "base_cos"),
        ("lzb:plane_reuse=0", "plane_reuse"),
        ("lzb:select=some,caster=octree", "select"),
        ("lzb:mode=fast", "mode"),
        ("lzb:pvl=some", "pvl"),
        ("lzb:caster=kd", "caster"),
        ("lzb:caster=bvh,bvh_leaf=0,pvl=leaves", "bvh_leaf"),
        ("lzb:caster=bvh,bvh_leaf=9,pvl=leaves", "bvh_leaf"),
        ("lzb:caster=octree,bvh_leaf=2", "caster=bvh"),
        ("lzb:leaf=many", "leaf"),
        ("lzb:mode=naive,payoff=on", "payoff"),
        ("lzb:pvl=leaves,packets=on", "mode=naive"),
        ("lzb:select=all", "pvl=leaves"),
        ("lzb:coherence=off", "pvl=leaves"),
        ("lzb:k=3", "pvl=leaves"),
        ("lzb:pvl=hits,packets=off", "packets=on"),
        ("lzb:pvl=hits,caster=octree", "caster=bvh"),
        ("lzb:mode=naive,pvl=hits", "mode=lazy"),
        ("lzb:mode=naive,caster=octree,packets=on", "caster=bvh"),
        ("lzb:mode=naive,packets=maybe", "packets"),
        ("lzb:payoff=maybe", "payoff"),
        ("lzb:oor=off,far_cull=on", "oor=on"),
        ("lzb:far_cull=maybe", "far_cull"),
        ("lzb:near_cull=off,near_temporal=on", "near_cull=on"),
        ("lzb:near_temporal=maybe", "near_temporal"),
    ] {
        match spec(bad).build(scene.clone(), &o) {
            Err(RenderError::BadParameter(m)) => assert!(m.contains(names), "{bad}: {m}"),
            Err(e) => panic!("{bad}: unexpected {e}"),
            Ok(_) => panic!("{bad} accepted"),
        }
    }
}

/// An octree that would explode at the depth asked (tiny leaves, deep) is built shallower,
/// within its reference budget, and frames stay identical.
#[test]
fn octrees_over_their_budget_are_built_shallower() {
    let built = occult_scenes::spec::parse_spec("terrain:g=64")
        .unwrap()
        .build()
        .unwrap();
    let scene = Arc::new(built.scene);
    let o = RenderOptions::default();
    let opts = occult_render::lzb::LzbOptions {
        leaf: Some(1),
        depth: 24,
        payoff: false,
        ..Default::default()
    };
    let mut lzb = occult_render::lzb::Lzb::new(scene.clone(), &o, &opts).expect("built within the budget");
    assert_eq!(lzb.shallower_octrees(), 1, "the terrain's one mesh");
    let deep_enough = occult_render::lzb::Lzb::new(scene.clone(), &o, &occult_render::lzb::LzbOptions::default())
        .expect("the default builds");
    assert_eq!(deep_enough.shallower_octrees(), 0);
    let view = View::new(built.default_camera, 96, 64).unwrap();
    let (mut a, mut b) = (Frame::new(96, 64).unwrap(), Frame::new(96, 64).unwrap());
    Algorithm::ZBUFFER
        .build(scene, &o)
        .unwrap()
        .render(&view, &mut a)
        .unwrap();
    lzb.render(&view, &mut b).unwrap();
    assert!(a.same_visibility(&b));
}

#[test]
fn counters_and_multithreaded_pvl_match_single_threaded() {
    let built = occult_scenes::spec::parse_spec("city:blocks=3,detail=2")
        .unwrap()
        .build()
        .unwrap();
    let scene = Arc::new(built.scene);
    let view = View::new(built.default_camera, 160, 120).unwrap();
    for caster in ["octree", "bvh"] {
        let mut counts = Vec::new();
        for threads in [1, 3] {
            let o = RenderOptions {
                raster: occult_raster::RasterConfig {
                    threads,
                    ..Default::default()
                },
                ..RenderOptions::default()
            };
            // The algorithm itself: with payoff a frame may be drawn directly, without rays;
            // the paper's plane, so that rays are cast (the cost plane may put every leaf near).
            let mut r = spec(&format!(
                "lzb:coherence=off,payoff=off,caster={caster},pvl=leaves,plane=dynamic"
            ))
            .build(scene.clone(), &o)
            .unwrap();
            let mut f = Frame::new(160, 120).unwrap();
            let s = r.render(&view, &mut f).unwrap();
            assert_eq!(s.rays_cast, s.counters.get("rays"));
            assert!(s.counters.get("ray_tri_tests") > 0 && s.nodes_visited > 0);
            assert!(s.phases.get(occult_render::Phase::Rays) > std::time::Duration::ZERO);
            counts.push((
                s.counters.get("pvl_triangles"),
                s.counters.get("pvl_leaves"),
                s.rays_cast,
            ));
        }
        // Without coherence each ray's path is independent of the split: the merged PVL is the
        // same.
        assert_eq!(counts[0], counts[1], "{caster}");
    }
}
