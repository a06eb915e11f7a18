//! The scene model: an instancing DAG of meshes and groups.
//!
//! A node is a [`Mesh`] or a group of `(parent_from_child, child)` [`Instance`]s. A node
//! referenced many times is stored once, so memory is O(unique geometry) while the number of
//! triangle instances can reach 10^14 (randomized z-buffer paper, §7.3). Bounds and triangle
//! counts are cached per node when it is added; children must exist before their parent, which
//! makes cycles impossible.
//!
//! **Item ids.** Triangle instances are numbered by their rank in the depth-first enumeration of
//! the DAG: the children of a group occupy consecutive id ranges in instance order, a mesh's
//! triangles consecutive ids in triangle order. An id is therefore unique and stable for a
//! scene, computable during any traversal (`base + item_offset(child)`), and equal to the
//! triangle's index in [`Scene::flatten`].

use crate::error::{CoreError, Result};
use crate::geom::Aabb;
use crate::mesh::Mesh;
use glam::{Affine3A, Vec3};

/// A triangle instance's 64-bit name (see the module doc).
pub type ItemId = u64;
/// "No triangle": the item of an uncovered pixel.
pub const NO_ITEM: ItemId = u64::MAX;
/// Default limit of [`Scene::flatten`], in triangle instances.
pub const MAX_FLATTEN_TRIANGLES: u64 = 64 << 20;
/// Deepest instancing chain accepted (root to mesh, in nodes).
pub const MAX_DEPTH: u32 = 64;

/// Index of a node in its [`Scene`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(pub u32);

impl NodeId {
    /// As an index into [`Scene::nodes`].
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// A reference to a child node placed by a transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// The child's placement in the parent's space.
    pub parent_from_child: Affine3A,
    /// The node placed.
    pub child: NodeId,
}

/// What a node holds.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeKind {
    /// Triangles.
    Mesh(Mesh),
    /// Instances of other nodes.
    Group(Vec<Instance>),
}

/// A node of the DAG, with its cached bounds and counts.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    name: String,
    kind: NodeKind,
    bounds: Aabb,
    item_count: u64,
    /// For a group: the first item id of instance `i`, relative to the group's first.
    item_offsets: Vec<u64>,
    depth: u32,
}

impl Node {
    /// The name given when it was added.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Mesh or group.
    pub fn kind(&self) -> &NodeKind {
        &self.kind
    }
    /// The mesh, for a mesh node.
    pub fn mesh(&self) -> Option<&Mesh> {
        match &self.kind {
            NodeKind::Mesh(m) => Some(m),
            NodeKind::Group(_) => None,
        }
    }
    /// The instances, for a group (empty for a mesh).
    pub fn instances(&self) -> &[Instance] {
        match &self.kind {
            NodeKind::Mesh(_) => &[],
            NodeKind::Group(g) => g,
        }
    }
    /// Bounds in the node's own space.
    #[inline]
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }
    /// Triangle instances below this node.
    #[inline]
    pub fn item_count(&self) -> u64 {
        self.item_count
    }
    /// First item id of instance `instance_index`, relative to this group's first.
    #[inline]
    pub fn item_offset(&self, instance_index: usize) -> u64 {
        self.item_offsets[instance_index]
    }
    /// Nodes on the longest path from here down to a mesh, this one included.
    pub fn depth(&self) -> u32 {
        self.depth
    }
}

/// Composes a child's transform under its parent's: `world_from_parent * parent_from_child`.
/// Every traversal uses this, walking down from the root, so that all renderers obtain
/// bit-identical matrices (and hence bit-identical frames) for the same instance.
#[inline]
pub fn compose(world_from_parent: &Affine3A, parent_from_child: &Affine3A) -> Affine3A {
    *world_from_parent * *parent_from_child
}

/// Where an item lives: its mesh node, triangle and placement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ItemLocation {
    /// The mesh node.
    pub mesh_node: NodeId,
    /// Triangle index within the mesh.
    pub triangle_index: u32,
    /// First item id of this mesh instance (names the instance).
    pub instance_base: ItemId,
    /// The instance's placement.
    pub world_from_object: Affine3A,
}

/// Builds a [`Scene`] bottom-up.
#[derive(Debug, Default)]
pub struct SceneBuilder {
    nodes: Vec<Node>,
}

impl SceneBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a mesh node (a mesh without triangles is allowed; it draws nothing).
    ///
    /// # Errors
    /// None today beyond [`Mesh`]'s own; returns `Result` so that limits can be added.
    pub fn add_mesh(&mut self, name: impl Into<String>, mesh: Mesh) -> Result<NodeId> {
        let node = Node {
            name: name.into(),
            bounds: mesh.bounds(),
            item_count: mesh.triangle_count() as u64,
            item_offsets: Vec::new(),
            kind: NodeKind::Mesh(mesh),
            depth: 1,
        };
        Ok(self.push(node))
    }

    /// Adds a group of instances of nodes added before.
    ///
    /// # Errors
    /// [`CoreError::UnknownNode`] for a child not yet added, [`CoreError::BadTransform`] for a
    /// non-finite or singular transform, [`CoreError::ItemOverflow`] past 2^64 items, and
    /// [`CoreError::EmptyScene`] if the chain below is deeper than 64 nodes.
    pub fn add_group(&mut self, name: impl Into<String>, instances: Vec<Instance>) -> Result<NodeId> {
        let name = name.into();
        let mut bounds = Aabb::EMPTY;
        let mut item_count = 0u64;
        let mut item_offsets = Vec::with_capacity(instances.len());
        let mut depth = 1;
        for (instance_index, inst) in instances.iter().enumerate() {
            let child = self
                .nodes
                .get(inst.child.index())
                .ok_or_else(|| CoreError::UnknownNode {
                    group: name.clone(),
                    instance_index,
                    child: inst.child.0,
                })?;
            let t = &inst.parent_from_child;
            if !t.is_finite() || t.matrix3.determinant() == 0.0 {
                return Err(CoreError::BadTransform {
                    group: name.clone(),
                    instance_index,
                });
            }
            bounds = bounds.union(child.bounds.transformed(t));
            item_offsets.push(item_count);
            item_count = item_count
                .checked_add(child.item_count)
                .ok_or_else(|| CoreError::ItemOverflow(name.clone()))?;
            depth = depth.max(child.depth + 1);
        }
        if depth > MAX_DEPTH {
            return Err(CoreError::EmptyScene(format!(
                "group '{name}' nests deeper than {MAX_DEPTH} levels"
            )));
        }
        if item_count == u64::MAX {
            // NO_ITEM must stay free.
            return Err(CoreError::ItemOverflow(name));
        }
        Ok(self.push(Node {
            name,
            kind: NodeKind::Group(instances),
            bounds,
            item_count,
            item_offsets,
            depth,
        }))
    }

    /// A builder holding `scene`'s nodes under their ids, to which a new root over some of
    /// them can be added (sort-last rendering builds each rank's part so: the part shares the
    /// scene's DAG, and its meshes keep their ids).
    ///
    /// Cost: a copy of every node, meshes included.
    pub fn from_scene(scene: &Scene) -> Self {
        Self {
            nodes: scene.nodes.clone(),
        }
    }

    /// Adds a group whose instance `i` takes the item ids from `first_items[i]` on, instead
    /// of the next free ones: a part of a scene built so keeps the scene's item ids (sort-last
    /// rendering composites ranks' frames by item id, which must be the scene's).
    /// `first_items` must be increasing and leave each instance room for its items; gaps
    /// are allowed (items of the gaps exist in no instance). The group's item count is the
    /// end of its last instance's range.
    ///
    /// # Errors
    /// As [`SceneBuilder::add_group`]; [`CoreError::EmptyScene`] when `first_items` and
    /// `instances` differ in length or the ranges overlap or are out of order.
    pub fn add_group_at_items(
        &mut self,
        name: impl Into<String>,
        instances: Vec<Instance>,
        first_items: Vec<ItemId>,
    ) -> Result<NodeId> {
        let name = name.into();
        if first_items.len() != instances.len() {
            return Err(CoreError::EmptyScene(format!(
                "group '{name}': {} instances but {} first items",
                instances.len(),
                first_items.len()
            )));
        }
        let id = self.add_group(name.clone(), instances)?;
        let node = &self.nodes[id.index()];
        let mut end = 0u64;
        for (i, inst) in node.instances().iter().enumerate() {
            let first = first_items[i];
            if first < end {
                return Err(CoreError::EmptyScene(format!(
                    "group '{name}': instance {i} starts at item {first}, inside the range of the one before"
                )));
            }
            end = first
                .checked_add(self.nodes[inst.child.index()].item_count)
                .ok_or_else(|| CoreError::ItemOverflow(name.clone()))?;
        }
        if end == u64::MAX {
            return Err(CoreError::ItemOverflow(name));
        }
        let node = &mut self.nodes[id.index()];
        node.item_offsets = first_items;
        node.item_count = end;
        Ok(id)
    }

    /// The node added as `id`, if any.
    pub fn node(&self, id: NodeId) -> Option<&Node> {
        self.nodes.get(id.index())
    }

    fn push(&mut self, node: Node) -> NodeId {
        self.nodes.push(node);
        NodeId((self.nodes.len() - 1) as u32)
    }

    /// Finishes the scene with `root` as its root (its space is world space).
    ///
    /// # Errors
    /// [`CoreError::UnknownNode`] for a missing root, [`CoreError::EmptyScene`] when the root
    /// holds no triangle.
    pub fn build(self, root: NodeId) -> Result<Scene> {
        let Some(r) = self.nodes.get(root.index()) else {
            return Err(CoreError::UnknownNode {
                group: "<root>".into(),
                instance_index: 0,
                child: root.0,
            });
        };
        if r.item_count == 0 {
            return Err(CoreError::EmptyScene(format!("root '{}' holds no triangle", r.name)));
        }
        Ok(Scene {
            nodes: self.nodes,
            root,
        })
    }
}

/// An instancing DAG with a root whose space is world space.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    nodes: Vec<Node>,
    root: NodeId,
}

impl Scene {
    /// A scene of one mesh.
    ///
    /// # Errors
    /// [`CoreError::EmptyScene`] when the mesh has no triangle.
    pub fn from_mesh(name: impl Into<String>, mesh: Mesh) -> Result<Self> {
        let mut b = SceneBuilder::new();
        let id = b.add_mesh(name, mesh)?;
        b.build(id)
    }

    /// The root node.
    #[inline]
    pub fn root(&self) -> NodeId {
        self.root
    }
    /// A node by id.
    ///
    /// # Panics
    /// If `id` is not a node of this scene (a programmer error: ids come from the scene).
    #[inline]
    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.index()]
    }
    /// All nodes; `NodeId(i)` is `nodes()[i]`.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }
    /// World-space bounds.
    pub fn bounds(&self) -> Aabb {
        self.node(self.root).bounds
    }
    /// Triangle instances in the scene (the size of the item id space).
    pub fn item_count(&self) -> u64 {
        self.node(self.root).item_count
    }
    /// Distinct triangles the scene shows: every mesh reachable from the root counted once,
    /// however often it is instanced. Meshes that no instance reaches (a builder may hold
    /// them) are left out, so this never exceeds [`Scene::item_count`].
    pub fn unique_triangle_count(&self) -> u64 {
        self.reachable_nodes()
            .filter_map(|n| n.mesh())
            .map(|m| m.triangle_count() as u64)
            .sum()
    }
    /// Instances stored in the groups reachable from the root (each group counted once).
    pub fn instance_count(&self) -> u64 {
        self.reachable_nodes().map(|n| n.instances().len() as u64).sum()
    }

    /// Vertex instances in the scene: every mesh's vertices times the instances of it that
    /// the root reaches (saturating). What drawing every mesh whole projects.
    pub fn vertex_instance_count(&self) -> u64 {
        // Instances of each node under the root, one pass down (children have smaller ids).
        let mut times = vec![0u64; self.nodes.len()];
        times[self.root.index()] = 1;
        let mut vertices = 0u64;
        for i in (0..=self.root.index()).rev() {
            let t = times[i];
            if t == 0 {
                continue;
            }
            let node = &self.nodes[i];
            if let Some(m) = node.mesh() {
                vertices = vertices.saturating_add(t.saturating_mul(m.positions().len() as u64));
            }
            for instance in node.instances() {
                let c = &mut times[instance.child.index()];
                *c = c.saturating_add(t);
            }
        }
        vertices
    }

    /// The nodes the root reaches, in storage order.
    fn reachable_nodes(&self) -> impl Iterator<Item = &Node> {
        self.nodes
            .iter()
            .zip(self.reachable())
            .filter(|&(_, r)| r)
            .map(|(n, _)| n)
    }

    /// Per node, whether the root reaches it. One pass from the root down: a group only
    /// refers to nodes added before it, so children have smaller ids than their parents.
    fn reachable(&self) -> Vec<bool> {
        let mut reachable = vec![false; self.nodes.len()];
        reachable[self.root.index()] = true;
        for i in (0..=self.root.index()).rev() {
            if reachable[i] {
                for instance in self.nodes[i].instances() {
                    reachable[instance.child.index()] = true;
                }
            }
        }
        reachable
    }
    /// Approximate bytes held by the scene (meshes, instances, offsets, names).
    pub fn memory_bytes(&self) -> usize {
        self.nodes
            .iter()
            .map(|n| {
                std::mem::size_of::<Node>()
                    + n.name.len()
                    + n.mesh().map_or(0, Mesh::memory_bytes)
                    + n.instances().len() * (std::mem::size_of::<Instance>() + 8)
            })
            .sum()
    }

    /// Calls `f(world_from_object, mesh_node, mesh, first_item)` for every mesh instance, in
    /// item order. Visits every instance: use only where brute force is meant.
    pub fn for_each_mesh_instance<'s>(&'s self, mut f: impl FnMut(&Affine3A, NodeId, &'s Mesh, ItemId)) {
        self.walk(self.root, &Affine3A::IDENTITY, 0, &mut f);
    }

    fn walk<'s>(
        &'s self,
        id: NodeId,
        world_from_node: &Affine3A,
        base: ItemId,
        f: &mut impl FnMut(&Affine3A, NodeId, &'s Mesh, ItemId),
    ) {
        let node = self.node(id);
        match &node.kind {
            NodeKind::Mesh(m) => f(world_from_node, id, m, base),
            NodeKind::Group(instances) => {
                for (i, inst) in instances.iter().enumerate() {
                    let world_from_child = compose(world_from_node, &inst.parent_from_child);
                    self.walk(inst.child, &world_from_child, base + node.item_offsets[i], f);
                }
            }
        }
    }

    /// Finds the mesh instance and triangle of an item. O(depth · log(instances per group)).
    pub fn resolve_item(&self, item: ItemId) -> Option<ItemLocation> {
        if item >= self.item_count() {
            return None;
        }
        let mut id = self.root;
        let mut local = item;
        let mut base = 0;
        let mut world = Affine3A::IDENTITY;
        loop {
            let node = self.node(id);
            match &node.kind {
                NodeKind::Mesh(_) => {
                    return Some(ItemLocation {
                        mesh_node: id,
                        triangle_index: local as u32,
                        instance_base: base,
                        world_from_object: world,
                    })
                }
                NodeKind::Group(instances) => {
                    // The last instance whose range starts at or before `local` and is non-empty.
                    let i = node.item_offsets.partition_point(|&o| o <= local).checked_sub(1)?;
                    let i = (0..=i).rev().find(|&j| self.node(instances[j].child).item_count > 0)?;
                    local -= node.item_offsets[i];
                    // A group built with `add_group_at_items` may leave gaps between ranges.
                    if local >= self.node(instances[i].child).item_count {
                        return None;
                    }
                    base += node.item_offsets[i];
                    world = compose(&world, &instances[i].parent_from_child);
                    id = instances[i].child;
                }
            }
        }
    }

    /// All triangle instances as one world-space mesh, in item order (triangle `i` is item `i`);
    /// per-triangle colors when any mesh has colors. For tests and small scenes only.
    ///
    /// # Errors
    /// [`CoreError::TooLargeToFlatten`] above `limit` triangle instances.
    pub fn flatten(&self, limit: u64) -> Result<Mesh> {
        let triangle_count = self.item_count();
        if triangle_count > limit {
            return Err(CoreError::TooLargeToFlatten { triangle_count, limit });
        }
        let any_color = self
            .nodes
            .iter()
            .any(|n| n.mesh().is_some_and(|m| m.colors().is_some()));
        let mut positions: Vec<Vec3> = Vec::new();
        let mut triangles = Vec::with_capacity(triangle_count as usize);
        let mut colors = Vec::new();
        self.for_each_mesh_instance(|world_from_object, _, mesh, _| {
            let first = positions.len() as u32;
            positions.extend(mesh.positions().iter().map(|&p| world_from_object.transform_point3(p)));
            triangles.extend(mesh.triangles().iter().map(|t| t.map(|i| i + first)));
            if any_color {
                colors
                    .extend((0..mesh.triangle_count()).map(|i| mesh.triangle_color(i).unwrap_or([200, 200, 200, 255])));
            }
        });
        let mesh = Mesh::new(positions, triangles)?;
        if any_color {
            mesh.with_colors(crate::MeshColors::PerTriangle(colors))
        } else {
            Ok(mesh)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Mesh {
        Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).expect("one in-range triangle is a valid mesh")
    }

    /// `count` instances of `child`, the `i`-th moved by `i × step`.
    fn row_of(child: NodeId, count: u32, step: Vec3) -> Vec<Instance> {
        (0..count)
            .map(|i| Instance {
                parent_from_child: Affine3A::from_translation(step * i as f32),
                child,
            })
            .collect()
    }

    fn two_level() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_mesh("tri", tri()).expect("a valid mesh adds");
        let g = b
            .add_group("row", row_of(m, 3, Vec3::X * 2.0))
            .expect("a row of a known node adds");
        let root = b
            .add_group("grid", row_of(g, 4, Vec3::Y * 2.0))
            .expect("a grid of a known node adds");
        b.build(root).expect("the grid has triangles and builds")
    }

    #[test]
    fn unreachable_meshes_are_not_counted() {
        // Variants built but never instanced (as generators with few placements leave them):
        // 1 + 1000 + 500 triangles stored, one triangle shown twice.
        let mut b = SceneBuilder::new();
        let big = |n: u32| {
            let p = (0..n + 2).map(|i| Vec3::new(i as f32, (i % 2) as f32, 0.0)).collect();
            Mesh::new(p, (0..n).map(|i| [i, i + 1, i + 2]).collect())
                .expect("a strip of in-range triangles is a valid mesh")
        };
        let used = b.add_mesh("used", tri()).expect("a valid mesh adds");
        let unused = b.add_mesh("unused", big(1000)).expect("a valid mesh adds");
        let _orphan = b.add_mesh("orphan", big(500)).expect("a valid mesh adds");
        let _unused_group = b
            .add_group("unused group", row_of(unused, 2, Vec3::Z))
            .expect("a row of a known node adds");
        let root = b
            .add_group("root", row_of(used, 2, Vec3::Z))
            .expect("a row of a known node adds");
        let s = b.build(root).expect("the root reaches a triangle and builds");
        assert_eq!(s.item_count(), 2);
        assert_eq!(s.unique_triangle_count(), 1);
        assert!(s.unique_triangle_count() <= s.item_count());
        assert_eq!(
            s.instance_count(),
            2,
            "the unreachable group's instances are not counted"
        );
        assert_eq!(
            s.vertex_instance_count(),
            6,
            "two instances of a 3-vertex triangle, nothing unreachable"
        );
        let one = Scene::from_mesh("one", tri()).expect("one triangle is a valid scene");
        assert_eq!((one.unique_triangle_count(), one.instance_count()), (1, 0));
    }

    #[test]
    fn counts_bounds_and_ids() {
        let s = two_level();
        assert_eq!(s.item_count(), 12);
        assert_eq!(s.unique_triangle_count(), 1);
        assert_eq!(s.instance_count(), 7);
        assert_eq!(s.vertex_instance_count(), 36, "12 instances of a 3-vertex triangle");
        assert_eq!(s.bounds(), Aabb::new(Vec3::ZERO, Vec3::new(5.0, 7.0, 0.0)));
        let mut items = vec![];
        s.for_each_mesh_instance(|_, _, _, base| items.push(base));
        assert_eq!(items, (0..12).collect::<Vec<_>>());
    }

    #[test]
    fn resolve_matches_flatten() {
        let s = two_level();
        let flat = s.flatten(100).expect("12 items are under the limit of 100");
        for item in 0..s.item_count() {
            let loc = s.resolve_item(item).expect("every item below item_count resolves");
            let mesh = s.node(loc.mesh_node).mesh().expect("an item resolves to a mesh node");
            let p = loc
                .world_from_object
                .transform_point3(mesh.triangle_positions(loc.triangle_index as usize)[0]);
            assert_eq!(p, flat.triangle_positions(item as usize)[0]);
        }
        assert!(s.resolve_item(12).is_none());
        assert!(s.resolve_item(NO_ITEM).is_none());
    }

    #[test]
    fn groups_at_items_keep_the_scene_ids() {
        // A part of `two_level` (12 items): its instances 0 and 2 of the root, at their ids.
        let s = two_level();
        let root = s.node(s.root());
        let picks = [0usize, 2];
        let instances = picks.iter().map(|&i| root.instances()[i]).collect();
        let firsts = picks.iter().map(|&i| root.item_offset(i)).collect();
        let mut b = SceneBuilder::from_scene(&s);
        let part_root = b
            .add_group_at_items("part", instances, firsts)
            .expect("first items ascending and in range");
        let part = b.build(part_root).expect("the part is a valid scene");
        let mut whole = vec![];
        s.for_each_mesh_instance(|w, _, _, base| whole.push((base, *w)));
        let mut parts = vec![];
        part.for_each_mesh_instance(|w, _, _, base| parts.push((base, *w)));
        let expected: Vec<_> = whole
            .into_iter()
            .filter(|(base, _)| {
                picks.iter().any(|&i| {
                    let first = root.item_offset(i);
                    (first..first + s.node(root.instances()[i].child).item_count()).contains(base)
                })
            })
            .collect();
        assert_eq!(parts, expected, "same ids, same placements");
        assert!(part.item_count() <= s.item_count());
        // An id in a gap (instance 1's range) names nothing.
        assert!(part.resolve_item(root.item_offset(1)).is_none());
        // Overlapping or mismatched ranges are errors.
        let mut b = SceneBuilder::from_scene(&s);
        let two = vec![root.instances()[0], root.instances()[0]];
        assert!(b.add_group_at_items("overlap", two.clone(), vec![0, 1]).is_err());
        assert!(b.add_group_at_items("short", two, vec![0]).is_err());
    }

    #[test]
    fn empty_and_bad_scenes_are_errors() {
        let mut b = SceneBuilder::new();
        let m = b
            .add_mesh("empty", Mesh::new(vec![], vec![]).expect("an empty mesh is valid"))
            .expect("an empty mesh adds");
        assert!(matches!(b.build(m), Err(CoreError::EmptyScene(_))));
        let mut b = SceneBuilder::new();
        assert!(matches!(
            b.add_group(
                "g",
                vec![Instance {
                    parent_from_child: Affine3A::IDENTITY,
                    child: NodeId(5)
                }]
            ),
            Err(CoreError::UnknownNode { .. })
        ));
        let m = b.add_mesh("tri", tri()).expect("a valid mesh adds");
        let bad = Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0));
        assert!(matches!(
            b.add_group(
                "g",
                vec![Instance {
                    parent_from_child: bad,
                    child: m
                }]
            ),
            Err(CoreError::BadTransform { .. })
        ));
        assert!(SceneBuilder::new().build(NodeId(0)).is_err());
    }

    #[test]
    fn flatten_limit_is_an_error() {
        assert!(matches!(
            two_level().flatten(5),
            Err(CoreError::TooLargeToFlatten { .. })
        ));
    }

    #[test]
    fn huge_instancing_counts_without_overflow() {
        let mut b = SceneBuilder::new();
        let mut id = b.add_mesh("tri", tri()).expect("a valid mesh adds");
        for level in 0..14 {
            id = b
                .add_group(format!("l{level}"), row_of(id, 10, Vec3::X))
                .expect("a row of a known node adds");
        }
        let s = b.build(id).expect("10^14 instances of a triangle build");
        assert_eq!(s.item_count(), 10u64.pow(14));
        let loc = s.resolve_item(10u64.pow(14) - 1).expect("the last item resolves");
        assert_eq!(loc.instance_base, 10u64.pow(14) - 1);
    }
}
