//! Precomputed sampling structures, one per node of the scene DAG (§5.3.1, §7.1, §7.3).

use occult_core::{Aabb, Affine3A, NodeId, NodeKind, Scene, Vec3};
use occult_spatial::{DistributionTree, OctreeConfigError, SampleOctree, SampleOctreeConfig};

/// Most area classes per mesh (§7.1): with ratio ≥ 1.01 this covers area ratios far beyond
/// `f32`'s range.
pub const MAX_AREA_CLASSES: usize = 64;

/// The sampling structure of one DAG node.
///
/// §7.3: every node gets its own octree; a group's entries are its instances (a pointer to the
/// child's structure and the transform), so memory is linear in unique geometry.
/// Deviation: the paper builds separate octrees only for nodes referenced more than once and
/// merges the others into their parent's octree; here every group keeps its own (a singly
/// referenced group then costs one extra transform per sample), because composing transforms
/// from the root, as every renderer must to get zbuffer's bits for the large-triangle
/// fallback, needs the instance chain.
pub struct Structure {
    /// §5.3.1/§7.1: the octrees (one per area class for meshes, one for groups).
    pub octree: SampleOctree,
    /// Total area in the node's own space.
    pub area: f64,
    /// Groups: item count before each list position (length entries + 1); empty for meshes.
    pub item_prefix: Vec<u64>,
    /// §5.3.4: the normal cone of each class (meshes with orientation classes; empty
    /// otherwise).
    pub cones: Vec<Cone>,
    /// Walker's alias table over the whole list, for picks from a whole structure.
    pub alias: AliasTable,
    /// Meshes: the triangles' positions in list order, so that a pick from the alias table
    /// reaches its vertices in one load instead of three dependent ones (entry, indices,
    /// positions); empty for groups.
    pub soup: Vec<[Vec3; 3]>,
    /// Groups: each list position's instance, in list order, so that a pick from the alias
    /// table reaches the child in one load instead of two dependent ones (entry, instance);
    /// empty for meshes.
    pub links: Vec<Link>,
    /// §5.4 (`dynamic=on`): the distribution tree over the octree's nodes; sampling and the
    /// areas and item counts of boxes then come from it, and entries can be removed and
    /// inserted. `None`: the static lists.
    pub tree: Option<DistributionTree>,
}

/// A group's list position as a descent reads it ([`Structure::links`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Link {
    /// The instance's transform: a descent carries its point up through the links it took,
    /// whose lines it has just read, instead of going back to the scene's instances.
    pub parent_from_child: occult_core::Affine3A,
    /// The instance's child node.
    pub child: u32,
    /// Items before the instance's first (the group's item offset of it).
    pub item_offset: u64,
}

/// Walker's alias table over list positions (weights = entry areas): one uniform number picks
/// a position with probability proportional to its area in O(1).
///
/// Deviation from §5.2: used for the samples of a whole structure (an entered instance);
/// sections of the list (the selected boxes) still invert the distribution list. Same
/// distribution, fewer dependent loads on deep instancing. Integer arithmetic only: the high
/// half of a random word picks the slot, the low half decides between it and its alias.
#[derive(Clone, Debug, Default)]
pub struct AliasTable {
    /// Per position: probability of keeping it (in units of 2^-32), and its alias (8 bytes, so
    /// that the table of a 20 K-triangle tree stays in the L2 cache).
    slots: Vec<(u32, u32)>,
}

impl AliasTable {
    /// The table of `weights` (non-negative, finite, positive sum); empty otherwise.
    pub fn new(weights: impl ExactSizeIterator<Item = f64>) -> Self {
        let n = weights.len();
        let w: Vec<f64> = weights.collect();
        let total: f64 = w.iter().sum();
        if n == 0 || !(total > 0.0 && total.is_finite()) {
            return Self::default();
        }
        // Vose's method.
        let mut scaled: Vec<f64> = w.iter().map(|&x| x * n as f64 / total).collect();
        let mut slots = vec![(u32::MAX, 0u32); n];
        let (mut small, mut large): (Vec<u32>, Vec<u32>) = (0..n as u32).partition(|&i| scaled[i as usize] < 1.0);
        while let (Some(&l), Some(&g)) = (small.last(), large.last()) {
            small.pop();
            slots[l as usize] = ((scaled[l as usize] * 4_294_967_296.0) as u32, g);
            scaled[g as usize] = (scaled[g as usize] + scaled[l as usize]) - 1.0;
            if scaled[g as usize] < 1.0 {
                large.pop();
                small.push(g);
            }
        }
        for i in large.into_iter().chain(small) {
            slots[i as usize] = (u32::MAX, i);
        }
        Self { slots }
    }

    /// True when there is no table.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The position picked by the uniformly random word `r`.
    #[inline]
    pub fn pick(&self, r: u64) -> u32 {
        let i = (((r >> 32) * self.slots.len() as u64) >> 32) as usize;
        let (keep, alias) = self.slots[i];
        if (r as u32) < keep {
            i as u32
        } else {
            alias
        }
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.slots.len() * 8
    }
}

/// A part of a structure's octree: the subtree of a node, or a node's own entries, with its
/// positions in the static list.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// The node.
    pub node: u32,
    /// Only the node's own entries (for a leaf both are the same).
    pub own: bool,
    /// Static list positions.
    pub range: std::ops::Range<u32>,
}

/// §5.3.4: the normals of an orientation class: every unit normal lies within `half_angle`
/// (radians, π when unbounded) of `axis`, in the mesh's own space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// Unit axis.
    pub axis: Vec3,
    /// Half opening angle in radians.
    pub half_angle: f32,
}

/// §5.3.4: the orientation class of unit normal `n` on a polar grid of `bands` bands of the polar
/// angle θ (from +z) and `2 · bands` sectors of the azimuth φ: `2 · bands²` classes.
pub fn orientation_class(n: Vec3, bands: u32) -> u32 {
    let b = bands.max(1);
    let theta = n.z.clamp(-1.0, 1.0).acos();
    let phi = n.y.atan2(n.x) + std::f32::consts::PI;
    let band = ((theta / std::f32::consts::PI * b as f32) as u32).min(b - 1);
    let sector = ((phi / std::f32::consts::TAU * (2 * b) as f32) as u32).min(2 * b - 1);
    band * 2 * b + sector
}

impl Structure {
    /// Summed area of `sec` (present entries only with a distribution tree).
    #[inline]
    pub fn section_area(&self, sec: &Section) -> f64 {
        match &self.tree {
            Some(t) if sec.own => t.own_sums(sec.node).area,
            Some(t) => t.subtree_sums(sec.node).area,
            None => self.octree.area(sec.range.clone()),
        }
    }

    /// Triangle instances in `sec` (present entries only with a distribution tree).
    #[inline]
    pub fn section_items(&self, sec: &Section) -> u64 {
        match &self.tree {
            Some(t) if sec.own => t.own_sums(sec.node).weight,
            Some(t) => t.subtree_sums(sec.node).weight,
            None => self.items(sec.range.clone()),
        }
    }

    /// Triangle instances in list positions `range`.
    #[inline]
    pub fn items(&self, range: std::ops::Range<u32>) -> u64 {
        if self.item_prefix.is_empty() {
            (range.end - range.start) as u64
        } else {
            self.item_prefix[range.end as usize] - self.item_prefix[range.start as usize]
        }
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        // The distribution tree: about one node (≈ 80 bytes) per octree node plus 24 bytes per
        // entry (id in a list, area, weight, location, home).
        let tree = self
            .tree
            .as_ref()
            .map_or(0, |t| t.node_count() * 80 + self.octree.entries().len() * 28);
        self.octree.memory_bytes()
            + self.item_prefix.len() * 8
            + tree
            + self.alias.memory_bytes()
            + self.soup.len() * std::mem::size_of::<[Vec3; 3]>()
            + self.links.len() * std::mem::size_of::<Link>()
    }
}

/// Area scale of a transform: `|det|^(2/3)`, exact for similarity transforms.
///
/// Deviation: for a non-uniform scale the area of a transformed triangle depends on its
/// orientation; the structures then sample in the child's own-space area distribution.
#[inline]
pub fn area_scale(t: &Affine3A) -> f64 {
    (t.matrix3.determinant().abs() as f64).powf(2.0 / 3.0)
}

/// Triangle area in object space.
#[inline]
pub fn triangle_area(p: [Vec3; 3]) -> f64 {
    0.5 * ((p[1] - p[0]).cross(p[2] - p[0]).length() as f64)
}

/// Builds the structure of every node (children before parents, as the DAG stores them).
///
/// `orientation` (§5.3.4): bands of the polar grid of orientation classes, 0 for none.
/// `dynamic` (§5.4): also build each node's distribution tree.
///
/// # Errors
/// [`OctreeConfigError`] for an octree configuration out of range.
pub fn build_all(
    scene: &Scene,
    config: &SampleOctreeConfig,
    area_ratio: f64,
    orientation: u32,
    dynamic: bool,
) -> Result<Vec<Structure>, OctreeConfigError> {
    use rayon::prelude::*;
    // Node areas first (groups need their children's), then the octrees in parallel.
    let mut areas = vec![0.0f64; scene.nodes().len()];
    let mesh_areas: Vec<f64> = scene
        .nodes()
        .par_iter()
        .map(|n| match n.kind() {
            NodeKind::Mesh(m) => (0..m.triangle_count())
                .map(|t| triangle_area(m.triangle_positions(t)))
                .filter(|a| a.is_finite())
                .sum(),
            NodeKind::Group(_) => 0.0,
        })
        .collect();
    for (i, n) in scene.nodes().iter().enumerate() {
        areas[i] = match n.kind() {
            NodeKind::Mesh(_) => mesh_areas[i],
            NodeKind::Group(g) => g
                .iter()
                .map(|inst| areas[inst.child.index()] * area_scale(&inst.parent_from_child))
                .sum(),
        };
    }
    (0..scene.nodes().len())
        .into_par_iter()
        .map(|i| {
            let mut st = build_one(scene, NodeId(i as u32), &areas, config, area_ratio, orientation)?;
            let o = &st.octree;
            st.alias = AliasTable::new((0..o.entries().len() as u32).map(|p| o.area(p..p + 1)));
            let node = scene.node(NodeId(i as u32));
            match node.kind() {
                NodeKind::Mesh(m) => {
                    st.soup = o.entries().iter().map(|&e| m.triangle_positions(e as usize)).collect();
                }
                NodeKind::Group(g) => {
                    st.links = o
                        .entries()
                        .iter()
                        .map(|&e| Link {
                            parent_from_child: g[e as usize].parent_from_child,
                            child: g[e as usize].child.0,
                            item_offset: node.item_offset(e as usize),
                        })
                        .collect();
                }
            }
            if dynamic {
                let (areas, weights) = entry_areas(scene, NodeId(i as u32), &areas);
                st.tree = Some(DistributionTree::from_octree(&st.octree, &areas, &weights));
            }
            Ok(st)
        })
        .collect()
}

/// Area and triangle-instance count of every entry of node `id` (triangles: own-space area, 1;
/// instances: the child's area scaled, its item count), as the static build weighs them.
pub fn entry_areas(scene: &Scene, id: NodeId, node_areas: &[f64]) -> (Vec<f64>, Vec<u64>) {
    match scene.node(id).kind() {
        NodeKind::Mesh(m) => (
            (0..m.triangle_count())
                .map(|t| triangle_area(m.triangle_positions(t)))
                .collect(),
            vec![1; m.triangle_count()],
        ),
        NodeKind::Group(g) => (
            g.iter()
                .map(|inst| node_areas[inst.child.index()] * area_scale(&inst.parent_from_child))
                .collect(),
            g.iter().map(|inst| scene.node(inst.child).item_count()).collect(),
        ),
    }
}

fn build_one(
    scene: &Scene,
    id: NodeId,
    areas: &[f64],
    config: &SampleOctreeConfig,
    area_ratio: f64,
    orientation: u32,
) -> Result<Structure, OctreeConfigError> {
    let node = scene.node(id);
    match node.kind() {
        NodeKind::Mesh(m) => {
            let n = m.triangle_count();
            let mut boxes = Vec::with_capacity(n);
            let mut tri_areas = Vec::with_capacity(n);
            for t in 0..n {
                let p = m.triangle_positions(t);
                boxes.push(Aabb::from_points(p));
                tri_areas.push(triangle_area(p));
            }
            // §7.1: classes of areas within a constant ratio of each other.
            let min_area = tri_areas
                .iter()
                .copied()
                .filter(|&a| a > 0.0 && a.is_finite())
                .fold(f64::INFINITY, f64::min);
            let log_ratio = area_ratio.ln();
            let classes: Vec<u32> = tri_areas
                .iter()
                .map(|&a| {
                    if a > 0.0 && a.is_finite() && min_area.is_finite() {
                        ((a / min_area).ln() / log_ratio)
                            .floor()
                            .clamp(0.0, (MAX_AREA_CLASSES - 1) as f64) as u32
                    } else {
                        0
                    }
                })
                .collect();
            let area_classes = classes.iter().copied().max().map_or(0, |c| c as usize + 1);
            if orientation == 0 {
                let octree = SampleOctree::build(&boxes, &tri_areas, &classes, area_classes, config)?;
                let area = octree.total_area();
                return Ok(Structure {
                    octree,
                    area,
                    item_prefix: Vec::new(),
                    cones: Vec::new(),
                    tree: None,
                    alias: AliasTable::default(),
                    soup: Vec::new(),
                    links: Vec::new(),
                });
            }
            // §5.3.4: class = area class × orientation class; each class's cone bounds the
            // normals of its triangles.
            let per = 2 * orientation * orientation;
            let normals: Vec<Vec3> = (0..n)
                .map(|t| {
                    let [a, b, c] = m.triangle_positions(t);
                    (b - a).cross(c - a).normalize_or_zero()
                })
                .collect();
            let classes: Vec<u32> = classes
                .iter()
                .zip(&normals)
                .map(|(&c, &nm)| c * per + orientation_class(nm, orientation))
                .collect();
            let class_count = area_classes * per as usize;
            let mut sums = vec![occult_core::glam::DVec3::ZERO; class_count];
            for (&c, &nm) in classes.iter().zip(&normals) {
                sums[c as usize] += nm.as_dvec3();
            }
            let axes: Vec<Vec3> = sums.iter().map(|s| s.normalize_or_zero().as_vec3()).collect();
            let mut half = vec![0.0f32; class_count];
            for (&c, &nm) in classes.iter().zip(&normals) {
                let a = axes[c as usize];
                let h = &mut half[c as usize];
                *h = if a == Vec3::ZERO || nm == Vec3::ZERO {
                    std::f32::consts::PI
                } else {
                    // Rounding margin: the bound must hold.
                    h.max(nm.dot(a).clamp(-1.0, 1.0).acos() + 1e-4)
                };
            }
            let cones = axes
                .into_iter()
                .zip(half)
                .map(|(axis, half_angle)| Cone {
                    axis,
                    half_angle: half_angle.min(std::f32::consts::PI),
                })
                .collect();
            let octree = SampleOctree::build(&boxes, &tri_areas, &classes, class_count, config)?;
            let area = octree.total_area();
            Ok(Structure {
                octree,
                area,
                item_prefix: Vec::new(),
                cones,
                tree: None,
                alias: AliasTable::default(),
                soup: Vec::new(),
                links: Vec::new(),
            })
        }
        NodeKind::Group(g) => {
            let boxes: Vec<Aabb> = g
                .iter()
                .map(|inst| scene.node(inst.child).bounds().transformed(&inst.parent_from_child))
                .collect();
            let inst_areas: Vec<f64> = g
                .iter()
                .map(|inst| areas[inst.child.index()] * area_scale(&inst.parent_from_child))
                .collect();
            let octree = SampleOctree::build(&boxes, &inst_areas, &vec![0; g.len()], 1, config)?;
            let mut item_prefix = Vec::with_capacity(octree.entries().len() + 1);
            let mut sum = 0u64;
            item_prefix.push(0);
            for &e in octree.entries() {
                sum = sum.saturating_add(scene.node(g[e as usize].child).item_count());
                item_prefix.push(sum);
            }
            let area = octree.total_area();
            Ok(Structure {
                octree,
                area,
                item_prefix,
                cones: Vec::new(),
                tree: None,
                alias: AliasTable::default(),
                soup: Vec::new(),
                links: Vec::new(),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn alias_table_picks_in_proportion_to_weights() {
        let w = [1.0, 0.0, 3.0, 0.5, 2.5, 1.0];
        let t = AliasTable::new(w.iter().copied());
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(4);
        let mut h = [0u32; 6];
        let n = 200_000;
        for _ in 0..n {
            h[t.pick(rng.random::<u64>()) as usize] += 1;
        }
        assert_eq!(h[1], 0);
        // χ² with 4 degrees of freedom: 25 is far beyond the 0.1 % point (18.5).
        let chi: f64 = w
            .iter()
            .zip(h)
            .filter(|(&w, _)| w > 0.0)
            .map(|(&w, c)| {
                let e = n as f64 * w / 8.0;
                (c as f64 - e).powi(2) / e
            })
            .sum();
        assert!(chi < 25.0, "chi² {chi}");
        assert!(AliasTable::new([0.0, 0.0].into_iter()).is_empty());
        assert_eq!(AliasTable::new([2.0].into_iter()).pick(u64::MAX), 0);
    }
}
