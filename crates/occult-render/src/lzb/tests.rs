//! Unit tests of the renderer's cost model, near pass and payoff.

use super::*;

/// Ten leaves of 1,000 triangles at distances 1..=10; coarse rays hitting at 1..=10 (and
/// one missing), each standing for 100 pixels.
fn case(ns_per_triangle: f64, ns_per_ray: f64) -> f32 {
    let leaves: Vec<(f32, u32)> = (1..=10).map(|d| (d as f32, 1000)).collect();
    let mut hits: Vec<Option<f32>> = (1..=10).map(|d| Some(d as f32 + 0.5)).collect();
    hits.push(None);
    cost_plane(
        &leaves,
        &hits,
        1100.0,
        ns_per_triangle,
        ns_per_ray,
        1.0,
        0.5,
        100.0,
        0.1,
        1000.0,
    )
}

/// Dear rays: everything near, nothing cast; cheap rays against dear triangles: the plane
/// at the nearest candidate, everything cast (half the far triangles in the PVL).
#[test]
fn the_cost_model_weighs_triangles_against_rays() {
    assert_eq!(case(10.0, 1e6), 1000.0, "rays dear: all near");
    assert_eq!(case(1e4, 1.0), 0.1, "rays cheap: the plane at the near plane");
    // Small leaves near, large ones far: the small ones drawn, the rest to the rays. The
    // plane sits at the hit just past the small leaves.
    let leaves: Vec<(f32, u32)> = (1..=10)
        .map(|d| (d as f32, if d <= 5 { 10 } else { 100_000 }))
        .collect();
    let hits: Vec<Option<f32>> = (1..=10).map(|d| Some(d as f32 + 0.5)).collect();
    let z = cost_plane(&leaves, &hits, 1000.0, 100.0, 2000.0, 1.0, 0.5, 100.0, 0.1, 1000.0);
    assert_eq!(z, 5.5);
}

/// The cost model's choice is the one of weighing every candidate over the leaves sorted by
/// distance (the model as first written), on random leaves and hits with ties, repeats and
/// leaves beyond every candidate.
#[test]
fn the_cost_plane_buckets_as_a_sort_would() {
    fn by_sort(leaves: &[(f32, u32)], hits: &[Option<f32>], rates: [f64; 6], near: f32, far: f32) -> f32 {
        let [pixels, ns_tri, ns_ray, near_share, pvl_share, ns_leaf] = rates;
        let mut by_distance = leaves.to_vec();
        by_distance.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut prefix = vec![0u64];
        for &(_, t) in &by_distance {
            prefix.push(prefix.last().copied().unwrap_or(0) + u64::from(t));
        }
        let mut hit_distances: Vec<f32> = hits.iter().flatten().copied().filter(|d| d.is_finite()).collect();
        hit_distances.sort_unstable_by(f32::total_cmp);
        let per_ray = pixels / hits.len().max(1) as f64;
        let cost = |z: f32| {
            let limit = z * (1.0 + NEAR_MARGIN);
            let n = by_distance.partition_point(|&(d, _)| d < limit);
            let near_t = prefix[n] as f64;
            let far_t = prefix[by_distance.len()] as f64 - near_t;
            let rays = (hit_distances.len() - hit_distances.partition_point(|&d| d < z)) as f64 * per_ray;
            (near_t * near_share + far_t * pvl_share) * ns_tri
                + rays * ns_ray
                + (by_distance.len() - n) as f64 * ns_leaf
        };
        std::iter::once(near)
            .chain(hit_distances.iter().copied())
            .chain(std::iter::once(far))
            .map(|z| z.clamp(near, far))
            .map(|z| (cost(z), z))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(near, |(_, z)| z)
    }
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
    for case in 0..500 {
        let leaves: Vec<(f32, u32)> = (0..rng.random_range(0..300))
            .map(|_| {
                let d = if rng.random_bool(0.2) {
                    rng.random_range(1..20) as f32
                } else {
                    rng.random_range(0.05..40.0f32)
                };
                (d, rng.random_range(1..5000))
            })
            .collect();
        let hits: Vec<Option<f32>> = (0..rng.random_range(1..40))
            .map(|_| {
                rng.random_bool(0.8)
                    .then(|| rng.random_range(1..20) as f32 * rng.random_range(0.9..1.1f32))
            })
            .collect();
        let rates = [
            rng.random_range(100.0..1e6),
            rng.random_range(1.0..100.0),
            rng.random_range(10.0..5000.0),
            rng.random_range(0.05..1.0),
            rng.random_range(0.0..1.0),
            rng.random_range(0.0..500.0),
        ];
        let [pixels, ns_tri, ns_ray, near_share, pvl_share, ns_leaf] = rates;
        let far = rng.random_range(10.0..50.0f32);
        assert_eq!(
            cost_plane(&leaves, &hits, pixels, ns_tri, ns_ray, near_share, pvl_share, ns_leaf, 0.1, far),
            by_sort(&leaves, &hits, rates, 0.1, far),
            "case {case}"
        );
    }
}

/// A wall of 12,800 triangles at z = 0 hiding another one at z = -2, both 4 × 4, a view of
/// them and its reference frame.
fn two_walls() -> (Arc<Scene>, View, Frame) {
    walls(4.0)
}

/// A wall of 12,800 triangles at z = 0, `near_size` wide, before another one at z = -2, 4 × 4
/// (partly seen around the first when that is less than about 2.4 wide), a view of them and
/// its reference frame.
fn walls(near_size: f32) -> (Arc<Scene>, View, Frame) {
    use occult_core::{Affine3A, Instance, SceneBuilder, Vec3};
    let mut b = SceneBuilder::new();
    let grid = b.add_mesh("grid", crate::test_grid(80)).expect("a grid");
    let at = |z: f32, size: f32| Instance {
        parent_from_child: Affine3A::from_translation(Vec3::new(-size / 2.0, -size / 2.0, z))
            * Affine3A::from_scale(Vec3::splat(size)),
        child: grid,
    };
    let root = b
        .add_group("walls", vec![at(0.0, near_size), at(-2.0, 4.0)])
        .expect("a group");
    let scene = Arc::new(b.build(root).expect("a scene"));
    let (view, _) = crate::test_view(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 96, 64);
    let reference = crate::tests::zbuffer_frame(&scene, &view);
    (scene, view, reference)
}

/// `near_cull=on`: with every leaf near, the units behind a wall are not drawn, and the
/// frame is the one drawn without culling (and `zbuffer`'s).
#[test]
fn near_cull_skips_what_the_near_pass_hides() {
    let (scene, view, reference) = two_walls();
    let options = RenderOptions::default();
    for near_cull in [true, false] {
        let opts = LzbOptions {
            plane: Plane::Static,
            plane_fraction: 1.0,
            payoff: false,
            near_cull,
            near_temporal: near_cull,
            ..LzbOptions::default()
        };
        let mut lzb = Lzb::new(scene.clone(), &options, &opts).expect("lzb builds");
        let mut frame = Frame::new(96, 64).expect("a frame");
        let stats = lzb.render(&view, &mut frame).expect("a frame");
        assert!(frame.same_visibility(&reference), "near_cull={near_cull}");
        assert_eq!(stats.counters.get("far_leaves"), 0, "every leaf near");
        let culled = stats.counters.get("near_culled_triangles");
        if near_cull {
            assert!(culled > 0, "the far wall is hidden");
            assert!(
                stats.triangles_submitted < 2 * 12_800 - 4096,
                "{} submitted",
                stats.triangles_submitted
            );
        } else {
            assert_eq!(culled, 0);
        }
    }
}

/// `near_temporal=on`: the second frame of a view draws the leaves that showed a pixel in the
/// first before any test, and culls the far wall as well; frames stay `zbuffer`'s. Off, no
/// leaf is drawn first.
#[test]
fn near_temporal_draws_last_frames_visible_leaves_first() {
    let (scene, view, reference) = two_walls();
    for near_temporal in [true, false] {
        let opts = LzbOptions {
            plane: Plane::Static,
            plane_fraction: 1.0,
            payoff: false,
            near_temporal,
            ..LzbOptions::default()
        };
        let mut lzb = Lzb::new(scene.clone(), &RenderOptions::default(), &opts).expect("lzb builds");
        let mut frame = Frame::new(96, 64).expect("a frame");
        let first = lzb.render(&view, &mut frame).expect("a frame");
        assert_eq!(first.counters.get("near_visible_triangles"), 0, "nothing seen yet");
        let second = lzb.render(&view, &mut frame).expect("a frame");
        assert!(frame.same_visibility(&reference), "near_temporal={near_temporal}");
        let drawn_first = second.counters.get("near_visible_triangles");
        if near_temporal {
            // The near wall's leaves alone (each wall has 12,800 triangles): the far wall
            // showed no pixel, and is culled.
            assert!(drawn_first > 0, "the near wall's leaves come first");
            assert!(drawn_first <= 12_800, "{drawn_first} drawn first");
            assert!(
                second.counters.get("near_culled_triangles") > 0,
                "the far wall is hidden"
            );
            assert!(second.triangles_submitted <= first.triangles_submitted);
            // In groups: a hidden group's units take one test.
            assert!(second.counters.get("near_culled_groups") > 0);
            assert!(second.counters.get("near_culled_units") > second.boxes_culled);
        } else {
            assert_eq!(drawn_first, 0);
        }
    }
}

/// A frame given up in its near pass (`crate::payoff`) tests nothing more: the rest of its near
/// set is drawn in one untested batch, no far leaf is projected, no ray cast, its far leaves
/// are drawn directly, and it is the reference frame, as is the next one; it is not drawn
/// again.
#[test]
fn a_frame_given_up_in_its_near_pass_finishes_directly() {
    use crate::direct::tests::ForceDirect;
    let (scene, view, reference) = two_walls();
    // The near wall near, the far one beyond the plane.
    let opts = LzbOptions {
        plane: Plane::Static,
        plane_fraction: 0.8,
        ..LzbOptions::default()
    };
    let full = {
        let mut lzb = Lzb::new(
            scene.clone(),
            &RenderOptions::default(),
            &LzbOptions {
                payoff: false,
                ..opts.clone()
            },
        )
        .expect("lzb builds");
        let mut frame = Frame::new(96, 64).expect("a frame");
        let stats = lzb.render(&view, &mut frame).expect("a frame");
        assert!(stats.counters.get("far_leaves") > 0);
        stats.counters.get("near_triangles")
    };
    let mut lzb = Lzb::new(scene, &RenderOptions::default(), &opts).expect("lzb builds");
    lzb.force(0, true);
    let mut frame = Frame::new(96, 64).expect("a frame");
    let stats = lzb.render(&view, &mut frame).expect("a frame");
    assert!(frame.same_visibility(&reference));
    assert_eq!(
        stats.counters.get(crate::direct::COUNTER),
        0,
        "finished, not drawn again"
    );
    assert_eq!(stats.counters.get("payoff_stopped"), 1);
    assert_eq!(stats.counters.get("oor_polygons"), 0, "no far leaf projected");
    assert_eq!(stats.counters.get("rays"), 0);
    assert!(
        stats.counters.get("far_direct_triangles") > 0,
        "the far wall drawn directly"
    );
    // Given up after its first batch, which is untested: nothing tested at all.
    assert_eq!(stats.counters.get("near_culled_triangles"), 0);
    let near = stats.counters.get("near_triangles");
    assert!(near >= full, "{near} near triangles drawn, {full} when not given up");
    lzb.force(0, false);
    let mut frame = Frame::new(96, 64).expect("a frame");
    lzb.render(&view, &mut frame).expect("a frame");
    assert!(frame.same_visibility(&reference), "the frame after");
}

/// `far_cull=on`: the far wall, wholly behind the near one, is dropped before object-oriented
/// ray casting (no polygon projected); the frame is the reference's either way.
#[test]
fn far_cull_drops_the_far_leaves_behind_the_near_set() {
    let (scene, view, reference) = two_walls();
    for far_cull in [true, false] {
        let opts = LzbOptions {
            plane: Plane::Static,
            plane_fraction: 0.8,
            payoff: false,
            far_cull,
            ..LzbOptions::default()
        };
        let mut lzb = Lzb::new(scene.clone(), &RenderOptions::default(), &opts).expect("lzb builds");
        let mut frame = Frame::new(96, 64).expect("a frame");
        let stats = lzb.render(&view, &mut frame).expect("a frame");
        assert!(frame.same_visibility(&reference), "far_cull={far_cull}");
        let far = stats.counters.get("far_leaves");
        assert!(far > 0, "the far wall lies beyond the plane");
        assert!(stats.counters.get("near_leaves") > 0, "the near wall before it");
        if far_cull {
            assert_eq!(stats.counters.get("far_culled_leaves"), far);
            assert_eq!(stats.counters.get("oor_polygons"), 0);
        } else {
            // The far wall reaches object-oriented ray casting, whose mask skips its instance:
            // its box lies on pixels all finished by the near wall.
            assert_eq!(stats.counters.get("far_culled_leaves"), 0);
            assert!(stats.counters.get("oor_polygons") + stats.counters.get("oor_instances_skipped") > 0);
        }
    }
    // A near wall too small to hide the far one (seen around it, over empty pixels too):
    // nothing dropped, rays cast, the reference frame.
    let (scene, view, reference) = walls(1.5);
    let opts = LzbOptions {
        plane: Plane::Static,
        plane_fraction: 0.8,
        payoff: false,
        ..LzbOptions::default()
    };
    let mut lzb = Lzb::new(scene, &RenderOptions::default(), &opts).expect("lzb builds");
    let mut frame = Frame::new(96, 64).expect("a frame");
    let stats = lzb.render(&view, &mut frame).expect("a frame");
    assert!(frame.same_visibility(&reference));
    assert!(stats.counters.get("far_leaves") > 0);
    assert_eq!(stats.counters.get("far_culled_leaves"), 0);
    assert!(stats.counters.get("rays") > 0);
}

/// §III.C's mask is marked in bands of rows, a few a thread: the pixels given a ray, and the
/// frame, do not depend on the threads.
#[test]
fn the_rays_cast_do_not_depend_on_the_threads() {
    // A near wall too small to hide the far one: far leaves left to the rays.
    let (scene, view, reference) = walls(1.5);
    let opts = LzbOptions {
        plane: Plane::Static,
        plane_fraction: 0.8,
        payoff: false,
        far_cull: false,
        ..LzbOptions::default()
    };
    let rays: Vec<u64> = [1, 2, 5]
        .into_iter()
        .map(|threads| {
            let mut ro = RenderOptions::default();
            ro.raster.threads = threads;
            let mut lzb = Lzb::new(scene.clone(), &ro, &opts).expect("lzb builds");
            let mut frame = Frame::new(96, 64).expect("a frame");
            let stats = lzb.render(&view, &mut frame).expect("a frame");
            assert!(frame.same_visibility(&reference), "{threads} threads");
            assert!(stats.counters.get("oor_polygons") > 0, "far leaves projected");
            stats.counters.get("rays")
        })
        .collect();
    assert!(rays[0] > 0);
    assert!(rays.iter().all(|&r| r == rays[0]), "rays cast: {rays:?}");
}

/// §III.C's mask marked in any number of bands of rows is the mask of one band: every leaf
/// of two walls far, over a pattern of unfinished pixels, seen from before them, and from so
/// near the first that its leaves cover the screen.
#[test]
fn the_oor_mask_does_not_depend_on_its_bands() {
    use occult_core::Vec3;
    let (scene, _, _) = walls(1.5);
    let lzb = Lzb::new(scene.clone(), &RenderOptions::default(), &LzbOptions::default()).expect("lzb builds");
    let (w, h) = (96u32, 64u32);
    let cast_mask: Vec<bool> = (0..w * h).map(|i| (i % w + i / w) % 3 != 0).collect();
    for (eye, whole) in [(Vec3::new(0.3, 0.2, 3.0), false), (Vec3::new(0.0, 0.0, 0.01), true)] {
        let (view, _) = crate::test_view(eye, Vec3::new(0.0, 0.0, -1.0), w, h);
        let mut instances = Vec::new();
        let mut far = Vec::new();
        scene.for_each_mesh_instance(|world_from_object, node, _, first_item| {
            let Accel::Mesh { octree, .. } = &lzb.accel[node.index()] else {
                return;
            };
            let inst = instances.len() as u32;
            far.extend(
                (0..octree.nodes().len() as u32)
                    .filter(|&n| octree.nodes()[n as usize].is_leaf() && octree.nodes()[n as usize].count > 0)
                    .map(|n| (inst, n)),
            );
            let rec = cast::InstanceRec {
                node,
                world_from_object: *world_from_object,
            };
            instances.push((rec, first_item, view.clip_from_object(world_from_object)));
        });
        let mark = |bands| {
            oor::mark(
                &cast_mask,
                &far,
                &instances,
                &lzb.accel,
                eye,
                [w, h],
                view.camera().near,
                bands,
            )
            .mask
        };
        let one = mark(1);
        assert!(one.iter().any(|&m| m), "some pixel marked");
        assert!(
            one.iter().zip(&cast_mask).all(|(&m, &c)| c || !m),
            "only unfinished pixels"
        );
        assert_eq!(one == cast_mask, whole, "the screen covered from near the wall");
        for bands in [0, 2, 3, 7, h - 1, h, h + 7] {
            assert!(mark(bands) == one, "{bands} bands, eye at {eye}");
        }
    }
}

/// A frame given up between waves of rays (`crate::payoff`; its near set drawn whole,
/// untested): no ray is cast, its far leaves are drawn directly, it is not drawn again, and
/// it is the reference frame.
#[test]
fn a_frame_given_up_before_its_rays_finishes_directly() {
    use crate::direct::tests::ForceDirect;
    // A near wall too small to hide the far one: far leaves left to the rays.
    let (scene, view, reference) = walls(1.5);
    let opts = LzbOptions {
        plane: Plane::Static,
        plane_fraction: 0.8,
        near_cull: false,
        near_temporal: false,
        ..LzbOptions::default()
    };
    let mut lzb = Lzb::new(scene, &RenderOptions::default(), &opts).expect("lzb builds");
    lzb.force(0, true);
    let mut frame = Frame::new(96, 64).expect("a frame");
    let stats = lzb.render(&view, &mut frame).expect("a frame");
    assert!(frame.same_visibility(&reference));
    assert_eq!(stats.counters.get("payoff_stopped"), 1);
    assert!(stats.counters.get("oor_polygons") > 0, "its far leaves were projected");
    assert_eq!(stats.counters.get("rays"), 0, "given up before the first wave");
    assert!(
        stats.counters.get("far_direct_triangles") > 0,
        "the far wall drawn directly"
    );
    assert_eq!(
        stats.counters.get(crate::direct::COUNTER),
        0,
        "finished, not drawn again"
    );
}

/// No leaf and no hit: nothing costs anything; the plane is the near plane.
#[test]
fn nothing_in_view_puts_the_plane_at_the_near_plane() {
    assert_eq!(
        cost_plane(&[], &[None, None], 100.0, 1.0, 1.0, 1.0, 0.5, 1.0, 0.1, 10.0),
        0.1
    );
}

/// The near pass's units of an instance all of whose leaves are near, made once when the
/// renderer is built ([`near_chunks`]), are the units it forms from a frame's leaves: the same
/// tests, the same triangles culled and drawn, frame after frame (the second with last frame's
/// leaves first), and the same frame.
#[test]
fn near_units_made_once_are_those_formed_per_frame() {
    let (scene, view, reference) = two_walls();
    let opts = LzbOptions {
        plane: Plane::Static,
        plane_fraction: 1.0,
        payoff: false,
        near_cull: true,
        near_temporal: true,
        ..LzbOptions::default()
    };
    let options = RenderOptions::default();
    let mut made_once = Lzb::new(scene.clone(), &options, &opts).expect("lzb builds");
    let mut per_frame = Lzb::new(scene.clone(), &options, &opts).expect("lzb builds");
    let mut chunks = 0;
    for accel in &mut per_frame.accel {
        if let Accel::Mesh { chunks: c, .. } = accel {
            chunks += c.len();
            c.clear();
        }
    }
    assert!(chunks > 2, "the walls' mesh has units made once");
    for frame_no in 0..2 {
        let (mut a, mut b) = (
            Frame::new(96, 64).expect("a frame"),
            Frame::new(96, 64).expect("a frame"),
        );
        let sa = made_once.render(&view, &mut a).expect("a frame");
        let sb = per_frame.render(&view, &mut b).expect("a frame");
        assert!(
            a.same_visibility(&reference) && b.same_visibility(&reference),
            "frame {frame_no}"
        );
        assert_eq!(sa.boxes_tested, sb.boxes_tested, "frame {frame_no}");
        assert_eq!(sa.triangles_submitted, sb.triangles_submitted, "frame {frame_no}");
        for counter in ["near_culled_units", "near_culled_groups", "near_visible_triangles"] {
            assert_eq!(
                sa.counters.get(counter),
                sb.counters.get(counter),
                "{counter}, frame {frame_no}"
            );
        }
        assert!(
            sa.counters.get("near_culled_units") > 0,
            "frame {frame_no}: the far wall is culled"
        );
    }
}

/// The near units' sort keys order as `f32::total_cmp` orders their distances, ties by index,
/// over signed, zero, infinite and neighbouring distances.
#[test]
fn distance_keys_order_as_total_cmp() {
    let ds = [
        f32::NEG_INFINITY,
        -3.5,
        -0.0,
        0.0,
        1e-30,
        0.25,
        0.25f32.next_up(),
        7.0,
        1e30,
        f32::INFINITY,
    ];
    for (i, &a) in ds.iter().enumerate() {
        for (j, &b) in ds.iter().enumerate() {
            let by_keys = super::near::distance_key(a, i as u32).cmp(&super::near::distance_key(b, j as u32));
            assert_eq!(by_keys, a.total_cmp(&b).then(i.cmp(&j)), "{a} ({i}) against {b} ({j})");
        }
    }
}

/// The near pass draws a leaf's own triangles as clusters and those it borrows when their
/// owner is not drawn: with the middle of the far wall hidden behind a narrower near one, the
/// far wall's drawn leaves at the edge of the hidden part borrow triangles whose owners are
/// culled, and the frame is still `zbuffer`'s (with and without last frame's leaves first).
#[test]
fn borrowed_triangles_of_hidden_owners_are_drawn() {
    let (scene, view, reference) = walls(1.5);
    for near_temporal in [false, true] {
        let opts = LzbOptions {
            plane: Plane::Static,
            plane_fraction: 1.0,
            payoff: false,
            leaf: Some(8),
            near_temporal,
            ..LzbOptions::default()
        };
        let mut lzb = Lzb::new(scene.clone(), &RenderOptions::default(), &opts).expect("lzb builds");
        let mut frame = Frame::new(96, 64).expect("a frame");
        for frame_no in 0..2 {
            let stats = lzb.render(&view, &mut frame).expect("a frame");
            assert!(
                frame.same_visibility(&reference),
                "near_temporal={near_temporal}, frame {frame_no}"
            );
            assert_eq!(stats.counters.get("far_leaves"), 0, "every leaf near");
            assert!(
                stats.counters.get("near_culled_units") > 0,
                "the far wall's middle is hidden"
            );
            assert!(
                stats.counters.get("near_borrowed_triangles") > 0,
                "leaves borrow triangles they do not own"
            );
        }
    }
}

/// A frame given up in its near pass, whose leaves borrow: instances drawn whole in its rest
/// drop the borrowed triangles their earlier clusters left for the last batch, and the far
/// leaves drawn directly see the near pass's marks; the frame is still `zbuffer`'s.
#[test]
fn a_frame_given_up_with_borrowing_leaves_is_identical() {
    use crate::direct::tests::ForceDirect;
    let (scene, view, reference) = walls(1.5);
    for plane_fraction in [1.0, 0.8] {
        let opts = LzbOptions {
            plane: Plane::Static,
            plane_fraction,
            leaf: Some(8),
            ..LzbOptions::default()
        };
        let mut lzb = Lzb::new(scene.clone(), &RenderOptions::default(), &opts).expect("lzb builds");
        lzb.force(0, true);
        let mut frame = Frame::new(96, 64).expect("a frame");
        let stats = lzb.render(&view, &mut frame).expect("a frame");
        assert!(frame.same_visibility(&reference), "plane at {plane_fraction}");
        assert_eq!(stats.counters.get("payoff_stopped"), 1, "given up");
        if plane_fraction < 1.0 {
            assert!(
                stats.counters.get("far_direct_triangles") > 0,
                "the far leaves drawn directly"
            );
        }
    }
}

/// `leaf=auto`: the paper's 150 on scenes of up to 150 × 16,384 triangle instances and where
/// the rays walk the octree (`caster=octree`); beyond, a leaf per 16,384th of the scene, at
/// most 16,384; a number given is kept. The octree is built with it, and each frame says it.
#[test]
fn auto_leaves_grow_with_the_scene_where_the_rays_do_not_walk_them() {
    assert_eq!(options::auto_leaf(0), options::PAPER_LEAF);
    assert_eq!(options::auto_leaf(2_457_600), 150);
    assert_eq!(options::auto_leaf(2_457_601), 151);
    assert_eq!(options::auto_leaf(29_467_866), 1_799);
    assert_eq!(options::auto_leaf(45_001_728), 2_747);
    assert_eq!(options::auto_leaf(16_384 * 16_384), options::AUTO_LEAF_MAX);
    assert_eq!(options::auto_leaf(16_384 * 16_384 + 1), options::AUTO_LEAF_MAX);
    assert_eq!(options::auto_leaf(u64::MAX), options::AUTO_LEAF_MAX);
    let spec = |s: &str| LzbOptions::from_params(&crate::AlgoSpec::parse(s).expect("parses").params).expect("valid");
    assert_eq!(spec("lzb").leaf, None);
    assert_eq!(spec("lzb:leaf=auto").leaf, None);
    let big = 29_467_866;
    for (s, leaf) in [
        ("lzb", 1_799),
        ("lzb:leaf= Auto ", 1_799),
        ("lzb:leaf=7", 7),
        ("lzb:caster=octree", 150),
        ("lzb:pvl=triangles", 150),
        ("lzb:pvl=leaves", 150),
        ("lzb:caster=bvh,pvl=leaves", 1_799),
        ("lzb:mode=naive", 1_799),
        ("lzb:mode=naive,caster=octree,packets=off", 150),
    ] {
        assert_eq!(spec(s).leaf_size_for(big), leaf, "{s}");
    }
    // Built with it: no leaf of the walls' octree holds more (its grid holds thousands).
    let (scene, view, _) = walls(1.5);
    let mut lzb = Lzb::new(scene, &RenderOptions::default(), &spec("lzb:leaf=9")).expect("lzb builds");
    assert_eq!(lzb.leaf_size(), 9);
    let leaves: Vec<u32> = lzb
        .accel
        .iter()
        .filter_map(|a| match a {
            Accel::Mesh { octree, .. } => Some(octree),
            _ => None,
        })
        .flat_map(|o| o.nodes().iter().filter(|n| n.is_leaf()).map(|n| n.count))
        .collect();
    assert!(leaves.len() > 1 && leaves.iter().all(|&c| c <= 9), "{leaves:?}");
    let mut frame = Frame::new(96, 64).expect("a frame");
    let stats = lzb.render(&view, &mut frame).expect("a frame");
    assert_eq!(stats.counters.get("octree_leaf"), 9);
}
