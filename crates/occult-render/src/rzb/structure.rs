//! Precomputed sampling structures, one per node of the scene DAG (§5.3.1, §7.1, §7.3).

use occult_core::{Aabb, Affine3A, NodeId, NodeKind, Scene, Vec3};
use occult_spatial::sample_octree::{SampleOctree, SampleOctreeConfig};

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
}

impl Structure {
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
        self.octree.memory_bytes() + self.item_prefix.len() * 8
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
pub fn build_all(scene: &Scene, config: &SampleOctreeConfig, area_ratio: f64) -> Vec<Structure> {
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
        .map(|i| build_one(scene, NodeId(i as u32), &areas, config, area_ratio))
        .collect()
}

fn build_one(scene: &Scene, id: NodeId, areas: &[f64], config: &SampleOctreeConfig, area_ratio: f64) -> Structure {
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
            let class_count = classes.iter().copied().max().map_or(0, |c| c as usize + 1);
            let octree = SampleOctree::build(&boxes, &tri_areas, &classes, class_count, config);
            let area = octree.total_area();
            Structure {
                octree,
                area,
                item_prefix: Vec::new(),
            }
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
            let octree = SampleOctree::build(&boxes, &inst_areas, &vec![0; g.len()], 1, config);
            let mut item_prefix = Vec::with_capacity(octree.entries().len() + 1);
            let mut sum = 0u64;
            item_prefix.push(0);
            for &e in octree.entries() {
                sum = sum.saturating_add(scene.node(g[e as usize].child).item_count());
                item_prefix.push(sum);
            }
            let area = octree.total_area();
            Structure {
                octree,
                area,
                item_prefix,
            }
        }
    }
}
