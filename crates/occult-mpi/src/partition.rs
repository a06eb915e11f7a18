//! Sort-last's geometry split: the scene's triangle instances shared among ranks so that each
//! rank's part is spatially compact (its frame covers little of the screen, its culling works)
//! and the parts cost about the same (triangle instances).
//!
//! 1. **Pieces.** The DAG is opened from the root, the costliest piece first, until there are
//!    [`PIECES_PER_RANK`] pieces per rank or none can be opened: opening a group makes its
//!    instances pieces (instanced scenes split their instances and share the DAG below them);
//!    opening a mesh cuts its triangles into [`MESH_CUTS`] runs of consecutive ids (generated
//!    and loaded meshes list triangles with spatial coherence, so runs are compact).
//! 2. **Assignment.** Recursive bisection of the pieces' centres along the longest axis of
//!    their bounds, cut where the cost splits in proportion to the ranks on each side (so any
//!    rank count, not only powers of two).
//! 3. **Parts.** A rank's part is a scene holding the whole DAG ([`SceneBuilder::from_scene`])
//!    and a new root over its pieces, each at its item ids in the whole scene
//!    ([`SceneBuilder::add_group_at_items`]): frames of parts composite by (depth, item id)
//!    into exactly the whole scene's frame.
//!
//! Cost: O(pieces · log pieces) for the split, and a copy of the scene's nodes per rank (a rank
//! holds the whole DAG; only its root differs).

use std::sync::Arc;

use occult_core::{compose, Aabb, Affine3A, Instance, ItemId, Mesh, NodeId, NodeKind, Scene, SceneBuilder};

/// Pieces per rank the opening aims at: enough for balance within a few percent when piece
/// costs are uneven, few enough that the parts' roots stay small.
pub const PIECES_PER_RANK: usize = 32;
/// Runs a mesh is cut into when it is opened.
pub const MESH_CUTS: u32 = 16;
/// Meshes with fewer triangles than this are never cut.
pub const MIN_CUT_TRIANGLES: u32 = 64;

/// A part of the scene: one placed node, or a run of a mesh's triangles.
#[derive(Clone, Debug)]
pub struct Piece {
    /// Its placement (composed from the root as every traversal composes it).
    pub world_from_object: Affine3A,
    /// The node placed.
    pub node: NodeId,
    /// The item id of its first triangle instance in the whole scene.
    pub first_item: ItemId,
    /// For a run of a mesh: its triangles (`start..end`, indices into the mesh).
    pub triangles: Option<(u32, u32)>,
    /// World-space bounds.
    pub bounds: Aabb,
    /// Triangle instances.
    pub cost: u64,
}

/// The pieces of `scene` for `ranks` ranks (step 1 of the module doc), in item order.
pub fn pieces(scene: &Scene, ranks: usize) -> Vec<Piece> {
    let target = ranks.max(1) * PIECES_PER_RANK;
    let root = scene.node(scene.root());
    let mut pieces = vec![Piece {
        world_from_object: Affine3A::IDENTITY,
        node: scene.root(),
        first_item: 0,
        triangles: None,
        bounds: root.bounds(),
        cost: root.item_count(),
    }];
    // Open the costliest openable piece until there are enough.
    let mut closed = vec![false];
    while pieces.len() < target {
        let Some(index) = (0..pieces.len())
            .filter(|&i| !closed[i])
            .max_by_key(|&i| pieces[i].cost)
        else {
            break;
        };
        match open(scene, &pieces[index]) {
            Some(children) if !children.is_empty() => {
                pieces.swap_remove(index);
                closed.swap_remove(index);
                closed.extend(children.iter().map(|_| false));
                pieces.extend(children);
            }
            _ => closed[index] = true,
        }
    }
    pieces.retain(|p| p.cost > 0);
    pieces.sort_by_key(|p| p.first_item);
    pieces
}

/// The pieces a piece opens into, `None` when it cannot be opened.
fn open(scene: &Scene, piece: &Piece) -> Option<Vec<Piece>> {
    let node = scene.node(piece.node);
    match node.kind() {
        NodeKind::Group(instances) => Some(
            instances
                .iter()
                .enumerate()
                .map(|(i, inst)| {
                    let child = scene.node(inst.child);
                    let world_from_child = compose(&piece.world_from_object, &inst.parent_from_child);
                    Piece {
                        world_from_object: world_from_child,
                        node: inst.child,
                        first_item: piece.first_item + node.item_offset(i),
                        triangles: None,
                        bounds: child.bounds().transformed(&world_from_child),
                        cost: child.item_count(),
                    }
                })
                .collect(),
        ),
        NodeKind::Mesh(mesh) => {
            let (start, end) = piece.triangles.unwrap_or((0, mesh.triangle_count() as u32));
            let count = end - start;
            if count < MIN_CUT_TRIANGLES {
                return None;
            }
            let step = count.div_ceil(MESH_CUTS);
            Some(
                (start..end)
                    .step_by(step as usize)
                    .map(|a| {
                        let b = (a + step).min(end);
                        let bounds = Aabb::from_points(
                            mesh.triangles()[a as usize..b as usize]
                                .iter()
                                .flat_map(|t| t.map(|v| mesh.positions()[v as usize])),
                        )
                        .transformed(&piece.world_from_object);
                        Piece {
                            world_from_object: piece.world_from_object,
                            node: piece.node,
                            first_item: piece.first_item + u64::from(a - start),
                            triangles: Some((a, b)),
                            bounds,
                            cost: u64::from(b - a),
                        }
                    })
                    .collect(),
            )
        }
    }
}

/// The rank of each piece (step 2 of the module doc): `result[i]` is piece `i`'s rank.
pub fn assign(pieces: &[Piece], ranks: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..pieces.len()).collect();
    let mut out = vec![0; pieces.len()];
    bisect(pieces, &mut order, 0, ranks.max(1), &mut out);
    out
}

fn bisect(pieces: &[Piece], order: &mut [usize], first_rank: usize, ranks: usize, out: &mut [usize]) {
    if ranks == 1 || order.len() <= 1 {
        for &i in order.iter() {
            out[i] = first_rank;
        }
        return;
    }
    let centres = Aabb::from_points(order.iter().map(|&i| pieces[i].bounds.center()));
    let size = centres.size();
    let axis = if size.x >= size.y && size.x >= size.z {
        0
    } else if size.y >= size.z {
        1
    } else {
        2
    };
    order.sort_by(|&a, &b| {
        let (ca, cb) = (pieces[a].bounds.center()[axis], pieces[b].bounds.center()[axis]);
        ca.total_cmp(&cb).then(pieces[a].first_item.cmp(&pieces[b].first_item))
    });
    let left_ranks = ranks / 2;
    let total: u64 = order.iter().map(|&i| pieces[i].cost).sum();
    let goal = total as f64 * left_ranks as f64 / ranks as f64;
    // The cut whose left cost is nearest the goal, leaving each side a piece where it can.
    let mut best = (f64::INFINITY, 1);
    let mut left = 0u64;
    for cut in 1..order.len() {
        left += pieces[order[cut - 1]].cost;
        let miss = (left as f64 - goal).abs();
        if miss < best.0 {
            best = (miss, cut);
        }
    }
    let (lo, hi) = order.split_at_mut(best.1);
    bisect(pieces, lo, first_rank, left_ranks, out);
    bisect(pieces, hi, first_rank + left_ranks, ranks - left_ranks, out);
}

/// Rank `rank`'s part of `scene` among `ranks` (step 3 of the module doc); `None` when the
/// split left it nothing (more ranks than pieces): it then draws nothing.
///
/// # Errors
/// Scene errors of building the part (none expected: its pieces come from a valid scene).
pub fn part(scene: &Scene, ranks: usize, rank: usize) -> occult_core::Result<Option<Arc<Scene>>> {
    let pieces = pieces(scene, ranks);
    let owner = assign(&pieces, ranks);
    let mine: Vec<&Piece> = pieces
        .iter()
        .zip(&owner)
        .filter(|(_, &r)| r == rank)
        .map(|(p, _)| p)
        .collect();
    if mine.is_empty() {
        return Ok(None);
    }
    let mut builder = SceneBuilder::from_scene(scene);
    let mut instances = Vec::with_capacity(mine.len());
    let mut firsts = Vec::with_capacity(mine.len());
    for piece in mine {
        let child = match piece.triangles {
            None => piece.node,
            Some((a, b)) => {
                let mesh = scene.node(piece.node).mesh().expect("runs are cut from meshes");
                builder.add_mesh(
                    format!("{} [{a}..{b}]", scene.node(piece.node).name()),
                    run_of(mesh, a, b)?,
                )?
            }
        };
        instances.push(Instance {
            parent_from_child: piece.world_from_object,
            child,
        });
        firsts.push(piece.first_item);
    }
    let root = builder.add_group_at_items(format!("rank {rank} of {ranks}"), instances, firsts)?;
    Ok(Some(Arc::new(builder.build(root)?)))
}

/// Triangles `a..b` of `mesh` as a mesh of their own (vertices renumbered, positions
/// bit-identical, so each triangle rasterizes exactly as in the whole mesh).
fn run_of(mesh: &Mesh, a: u32, b: u32) -> occult_core::Result<Mesh> {
    let mut index_of = std::collections::HashMap::new();
    let mut positions = Vec::new();
    let triangles = mesh.triangles()[a as usize..b as usize]
        .iter()
        .map(|t| {
            t.map(|v| {
                *index_of.entry(v).or_insert_with(|| {
                    positions.push(mesh.positions()[v as usize]);
                    (positions.len() - 1) as u32
                })
            })
        })
        .collect();
    Mesh::new(positions, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::Vec3;

    fn grid_scene(n: u32) -> Scene {
        let tri = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).expect("a triangle");
        let mut b = SceneBuilder::new();
        let m = b.add_mesh("tri", tri).expect("valid");
        let row = (0..n)
            .map(|i| Instance {
                parent_from_child: Affine3A::from_translation(Vec3::X * 2.0 * i as f32),
                child: m,
            })
            .collect();
        let r = b.add_group("row", row).expect("valid");
        b.build(r).expect("valid")
    }

    #[test]
    fn every_item_is_in_exactly_one_part() {
        let scene = grid_scene(100);
        for ranks in 1..=5 {
            let mut items = Vec::new();
            for rank in 0..ranks {
                if let Some(p) = part(&scene, ranks, rank).expect("valid parts") {
                    p.for_each_mesh_instance(|_, _, m, base| items.extend(base..base + m.triangle_count() as u64));
                }
            }
            items.sort_unstable();
            assert_eq!(items, (0..100).collect::<Vec<_>>(), "{ranks} ranks");
        }
    }

    #[test]
    fn parts_are_balanced_and_compact() {
        let scene = grid_scene(128);
        let pieces = pieces(&scene, 4);
        let owner = assign(&pieces, 4);
        for rank in 0..4 {
            let mine: Vec<_> = pieces.iter().zip(&owner).filter(|(_, &r)| r == rank).collect();
            assert_eq!(mine.len(), 32, "equal costs split evenly");
            let xs: Vec<f32> = mine.iter().map(|(p, _)| p.bounds.center().x).collect();
            let span = xs.iter().cloned().fold(f32::MIN, f32::max) - xs.iter().cloned().fold(f32::MAX, f32::min);
            assert!(span < 2.0 * 33.0, "a quarter of the row, not scattered");
        }
    }

    #[test]
    fn one_mesh_is_cut_into_runs_and_more_ranks_than_pieces_leave_some_empty() {
        let n = 200u32;
        let positions = (0..n + 2).map(|i| Vec3::new(i as f32, (i % 2) as f32, 0.0)).collect();
        let mesh = Mesh::new(positions, (0..n).map(|i| [i, i + 1, i + 2]).collect()).expect("a strip");
        let scene = Scene::from_mesh("strip", mesh).expect("valid");
        let ps = pieces(&scene, 2);
        assert!(ps.len() > 1 && ps.iter().all(|p| p.triangles.is_some()));
        assert_eq!(ps.iter().map(|p| p.cost).sum::<u64>(), u64::from(n));
        let tiny = Scene::from_mesh(
            "tri",
            Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).expect("a triangle"),
        )
        .expect("valid");
        assert!(part(&tiny, 3, 0).expect("valid").is_some());
        assert!(part(&tiny, 3, 2).expect("valid").is_none());
    }
}
