//! The sample octree of the randomized z-buffer: an octree with shortcuts and extended boxes
//! whose nodes own sections of one global distribution list, the sample-selection structure.
//!
//! # References
//! - Wand et al. 2001 (`papers/randomized-z-buffer-wand-2001.txt`):
//!   - §5.2 *distribution lists*: prefix sums of (unprojected) areas; a uniform number scaled by
//!     the total area, inverted by binary search, picks an entry with probability proportional
//!     to its area in O(log n);
//!   - §5.3.1 *spatial classification*: an octree with *shortcuts* (inner nodes with a single
//!     child are not stored) and *extended boxes* (the cell grown by a constant factor); an
//!     entry that crosses the grid is stored in the smallest node whose extended box holds it;
//!     one global list whose sections belong to the nodes: a node's section is the
//!     concatenation of its children's sections followed by its own entries (Figure 5);
//!   - §7.1 *area classes*: one octree per class, all in the same global list (see
//!     [`SampleOctree::build`]);
//!   - §5.4 *dynamic updates*: [`DistributionTree`], summed areas per octree node, insertion
//!     and removal in O(height), sampling by descending from a node.
//!
//! Entries are opaque: boxes with areas (triangles of a mesh, instances of a group). The
//! octree stores for every node the tight bounds of its section (for depth ranges, tighter than
//! the extended cell) and of its own entries.
//!
//! Cost: build O(n log n) (one pass over the entries per level); memory O(n): 12 bytes per
//! entry (index + prefix sum) and one 84-byte node per stored node, at most about 2n/leaf_size
//! nodes thanks to shortcuts.

use super::cell::{self, child_min, octant_of, stops_splitting, OctreeConfigError};
use occult_core::{Aabb, Vec3};

/// Tunables of [`SampleOctree::build`].
#[derive(Clone, Debug, PartialEq)]
pub struct SampleOctreeConfig {
    /// Entries a leaf may hold (≥ 1): smaller gives finer depth classification, more nodes.
    pub leaf_size: usize,
    /// Growth of a child's cell into its extended box, as a fraction of the cell side on each
    /// side (finite, ≥ 0; §5.3.1 "enlarged by a constant factor"). 0.5 doubles the side.
    pub extension: f32,
    /// Deepest level (cells halved this many times, 0..=[`cell::MAX_OCTREE_DEPTH`]), a guard
    /// against coincident entries.
    pub max_depth: u32,
}

impl SampleOctreeConfig {
    /// Checks the leaf size, the extension (finite, ≥ 0), then the depth, by the rules of
    /// [`super::cell`] (the build calls it first; nothing is clamped).
    ///
    /// # Errors
    /// [`OctreeConfigError`] naming `leaf_size`, `extension` or `max_depth` and the value out
    /// of range.
    pub fn validate(&self) -> Result<(), OctreeConfigError> {
        cell::check_leaf_size("leaf_size", self.leaf_size)?;
        cell::check_fraction("extension", self.extension, 0.0, f32::MAX)?;
        cell::check_depth("max_depth", self.max_depth, 0)
    }
}

impl Default for SampleOctreeConfig {
    fn default() -> Self {
        Self {
            leaf_size: 32,
            extension: 0.25,
            max_depth: 48,
        }
    }
}

/// A stored node (§5.3.1). `first..own_first` is the children's part of its section,
/// `own_first..end` its own entries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleOctreeNode {
    /// Tight bounds of every entry of the section.
    pub bounds: Aabb,
    /// Tight bounds of the node's own entries (empty when none).
    pub own_bounds: Aabb,
    /// The cell (before extension), for dynamic insertion.
    pub cell_min: Vec3,
    /// Side of the (cubical) cell.
    pub cell_side: f32,
    /// First position of the section in the global list.
    pub first: u32,
    /// First position of the node's own entries.
    pub own_first: u32,
    /// One past the section's last position.
    pub end: u32,
    /// Index of the first child; children are contiguous.
    pub first_child: u32,
    /// Number of stored children (0 for a leaf).
    pub child_count: u32,
}

const _: () = assert!(std::mem::size_of::<SampleOctreeNode>() == 84);

impl SampleOctreeNode {
    /// True when it has no stored child.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.child_count == 0
    }
    /// The children's indices.
    #[inline]
    pub fn children(&self) -> std::ops::Range<u32> {
        self.first_child..self.first_child + self.child_count
    }
    /// The whole section (positions in the global list).
    #[inline]
    pub fn section(&self) -> std::ops::Range<u32> {
        self.first..self.end
    }
    /// The node's own entries (positions in the global list).
    #[inline]
    pub fn own(&self) -> std::ops::Range<u32> {
        self.own_first..self.end
    }
}

/// Octrees (one per class) over one global distribution list.
#[derive(Clone, Debug, Default)]
pub struct SampleOctree {
    nodes: Vec<SampleOctreeNode>,
    /// Entry index at each list position.
    entries: Vec<u32>,
    /// `prefix[i]`: summed area of positions `0..i` (length `entries + 1`).
    prefix: Vec<f64>,
    /// Root node of each class (`None` for a class without entries).
    roots: Vec<Option<u32>>,
    config: SampleOctreeConfig,
}

impl SampleOctree {
    /// Builds one octree per class over entries `i` with box `boxes[i]`, area `areas[i]` and
    /// class `classes[i]` (`< class_count`). Entries of zero or non-finite area, or with an
    /// empty box, are left out (they can never be sampled).
    ///
    /// # Errors
    /// [`OctreeConfigError`] for a configuration out of range ([`SampleOctreeConfig::validate`]).
    ///
    /// # Panics
    /// If the slices differ in length or a class is out of range (programmer errors).
    pub fn build(
        boxes: &[Aabb],
        areas: &[f64],
        classes: &[u32],
        class_count: usize,
        config: &SampleOctreeConfig,
    ) -> Result<Self, OctreeConfigError> {
        assert!(
            boxes.len() == areas.len() && areas.len() == classes.len(),
            "entry slices differ in length"
        );
        assert!(boxes.len() < u32::MAX as usize, "too many entries");
        config.validate()?;
        let mut per_class: Vec<Vec<u32>> = vec![Vec::new(); class_count];
        for i in 0..boxes.len() {
            let a = areas[i];
            if a > 0.0 && a.is_finite() && !boxes[i].is_empty() && boxes[i].min.is_finite() && boxes[i].max.is_finite()
            {
                per_class[classes[i] as usize].push(i as u32);
            }
        }
        let mut b = Builder {
            boxes,
            config,
            nodes: Vec::new(),
            entries: Vec::with_capacity(boxes.len()),
        };
        let mut roots = Vec::with_capacity(class_count);
        for ents in per_class {
            if ents.is_empty() {
                roots.push(None);
                continue;
            }
            let bounds = ents.iter().fold(Aabb::EMPTY, |acc, &i| acc.union(boxes[i as usize]));
            let side = bounds.size().max_element().max(f32::MIN_POSITIVE) * (1.0 + 1e-4);
            let slot = b.nodes.len() as u32;
            b.nodes.push(placeholder());
            b.node(slot, bounds.min, side, ents, 0);
            roots.push(Some(slot));
        }
        let mut prefix = Vec::with_capacity(b.entries.len() + 1);
        let mut sum = 0.0f64;
        prefix.push(0.0);
        for &e in &b.entries {
            sum += areas[e as usize];
            prefix.push(sum);
        }
        Ok(Self {
            nodes: b.nodes,
            entries: b.entries,
            prefix,
            roots,
            config: config.clone(),
        })
    }

    /// All nodes.
    #[inline]
    pub fn nodes(&self) -> &[SampleOctreeNode] {
        &self.nodes
    }
    /// The root of each class.
    #[inline]
    pub fn roots(&self) -> &[Option<u32>] {
        &self.roots
    }
    /// Entry index at each list position.
    #[inline]
    pub fn entries(&self) -> &[u32] {
        &self.entries
    }
    /// The configuration it was built with.
    pub fn config(&self) -> &SampleOctreeConfig {
        &self.config
    }
    /// Summed area of list positions `range`.
    #[inline]
    pub fn area(&self, range: std::ops::Range<u32>) -> f64 {
        self.prefix[range.end as usize] - self.prefix[range.start as usize]
    }
    /// Summed area of the whole list.
    #[inline]
    pub fn total_area(&self) -> f64 {
        *self.prefix.last().unwrap_or(&0.0)
    }

    /// §5.2: the list position in `range` whose area interval holds `u ∈ [0, 1)` scaled to the
    /// range's area: an entry chosen with probability proportional to its area. Binary search,
    /// O(log n). Never returns a zero-area entry.
    ///
    /// # Panics
    /// If `range` is empty or has no area (a programmer error: such ranges are never sampled).
    #[inline]
    pub fn pick(&self, range: std::ops::Range<u32>, u: f64) -> u32 {
        let lo = self.prefix[range.start as usize];
        let hi = self.prefix[range.end as usize];
        debug_assert!(hi > lo, "sampling a section without area");
        self.locate(range, lo + u * (hi - lo))
    }

    /// The list position in `range` whose area interval (measured from the list's start)
    /// holds `target`; targets beyond the range's end give its last entry with area.
    #[inline]
    pub fn locate(&self, range: std::ops::Range<u32>, target: f64) -> u32 {
        let hi = self.prefix[range.end as usize];
        // First position p with prefix[p + 1] > target: the entry whose interval holds it.
        let s = &self.prefix[range.start as usize + 1..=range.end as usize];
        let mut k = s.partition_point(|&c| c <= target);
        if k == s.len() {
            // Rounding put the target at `hi`: take the last entry that has area.
            k = s.partition_point(|&c| c < hi);
        }
        range.start + k as u32
    }

    /// Summed area before list position `pos`.
    #[inline]
    pub fn prefix(&self, pos: u32) -> f64 {
        self.prefix[pos as usize]
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<SampleOctreeNode>() + self.entries.len() * 4 + self.prefix.len() * 8
    }
}

fn placeholder() -> SampleOctreeNode {
    SampleOctreeNode {
        bounds: Aabb::EMPTY,
        own_bounds: Aabb::EMPTY,
        cell_min: Vec3::ZERO,
        cell_side: 0.0,
        first: 0,
        own_first: 0,
        end: 0,
        first_child: 0,
        child_count: 0,
    }
}

/// The octant of `p` in the cell `(min, side)`, and that child's cell minimum.
#[inline]
fn octant(min: Vec3, side: f32, p: Vec3) -> (usize, Vec3) {
    let center = min + Vec3::splat(0.5 * side);
    let k = octant_of(center, p);
    (k, child_min(min, center, k))
}

/// The extended box of the cell `(min, side)` (§5.3.1).
#[inline]
fn extended(min: Vec3, side: f32, extension: f32) -> Aabb {
    let m = Vec3::splat(side * extension);
    Aabb::new(min - m, min + Vec3::splat(side) + m)
}

#[inline]
fn contains(outer: &Aabb, inner: &Aabb) -> bool {
    outer.min.cmple(inner.min).all() && inner.max.cmple(outer.max).all()
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    config: &'a SampleOctreeConfig,
    nodes: Vec<SampleOctreeNode>,
    entries: Vec<u32>,
}

impl Builder<'_> {
    /// Fills node `slot` for `ents` in the cell `(min, side)` at `depth`.
    fn node(&mut self, slot: u32, mut min: Vec3, mut side: f32, ents: Vec<u32>, mut depth: u32) {
        let bounds = ents
            .iter()
            .fold(Aabb::EMPTY, |acc, &i| acc.union(self.boxes[i as usize]));
        let first = self.entries.len() as u32;
        let (mut own, buckets) = loop {
            if stops_splitting(ents.len(), self.config.leaf_size, depth, self.config.max_depth) {
                break (ents, Vec::new());
            }
            let mut own = Vec::new();
            let mut buckets: Vec<(Vec3, Vec<u32>)> = Vec::new();
            let mut child_of = [usize::MAX; 8];
            let half = 0.5 * side;
            for &i in &ents {
                let b = self.boxes[i as usize];
                let (k, cmin) = octant(min, side, b.center());
                if contains(&extended(cmin, half, self.config.extension), &b) {
                    if child_of[k] == usize::MAX {
                        child_of[k] = buckets.len();
                        buckets.push((cmin, Vec::new()));
                    }
                    buckets[child_of[k]].1.push(i);
                } else {
                    own.push(i);
                }
            }
            if own.is_empty() && buckets.len() == 1 {
                // Shortcut (§5.3.1): a node with a single child is not stored; descend.
                min = buckets[0].0;
                side = half;
                depth += 1;
                continue;
            }
            break (own, buckets);
        };
        let first_child = self.nodes.len() as u32;
        let child_count = buckets.len() as u32;
        for _ in 0..child_count {
            self.nodes.push(placeholder());
        }
        for (j, (cmin, list)) in buckets.into_iter().enumerate() {
            self.node(first_child + j as u32, cmin, 0.5 * side, list, depth + 1);
        }
        let own_first = self.entries.len() as u32;
        own.sort_unstable();
        let own_bounds = own
            .iter()
            .fold(Aabb::EMPTY, |acc, &i| acc.union(self.boxes[i as usize]));
        self.entries.extend_from_slice(&own);
        self.nodes[slot as usize] = SampleOctreeNode {
            bounds,
            own_bounds,
            cell_min: min,
            cell_side: side,
            first,
            own_first,
            end: self.entries.len() as u32,
            first_child: if child_count == 0 { 0 } else { first_child },
            child_count,
        };
    }
}

/// §5.4: the octree used as a *distribution tree*: every node stores the summed area (and a
/// summed integer weight, e.g. triangle count) of its subtree and of its own entries, and keeps
/// its own entries in a list that can grow and shrink, so that entries (a triangle, or an
/// instance with its own structure) are inserted and removed in O(height) and sampled by
/// descending from any node in O(height · leaf size).
///
/// Built as a mirror of every node of a [`SampleOctree`] (same node indices, cells and class
/// roots). Own lists stay sorted by entry id (the static list's order) and sums are recomputed
/// along the path in a fixed order (own entries, then children) rather than adjusted by
/// differences, so the tree's state, and hence every sample drawn from it, depends only on
/// which entries are present, not on the history of insertions and removals.
///
/// Insertion either descends by the static rule (the first stored child whose extended box
/// holds the entry, [`DistributionTree::insert`]) or goes to a given node, such as the entry's
/// node in the static build ([`DistributionTree::insert_at`]). Deviation: new entries never
/// split leaves or create nodes (the paper rebalances through its octree operations); a leaf
/// that receives many insertions samples in time linear in its length.
#[derive(Clone, Debug)]
pub struct DistributionTree {
    nodes: Vec<DynNode>,
    roots: Vec<Option<u32>>,
    /// Node holding each entry id (`u32::MAX`: absent).
    location: Vec<u32>,
    /// Node of each entry in the static build (`u32::MAX`: none).
    home: Vec<u32>,
    area: Vec<f64>,
    weight: Vec<u64>,
    extension: f32,
}

/// Summed area and weight of a set of entries of a [`DistributionTree`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sums {
    /// Summed area.
    pub area: f64,
    /// Summed weight (saturating).
    pub weight: u64,
}

impl Sums {
    /// These sums and one more term, added in that order (the order fixes the bits).
    #[inline]
    fn add(self, area: f64, weight: u64) -> Self {
        Self {
            area: self.area + area,
            weight: self.weight.saturating_add(weight),
        }
    }
}

#[derive(Clone, Debug)]
struct DynNode {
    cell_min: Vec3,
    cell_side: f32,
    parent: u32,
    children: std::ops::Range<u32>,
    own: Vec<u32>,
    own_sums: Sums,
    subtree_sums: Sums,
}

impl DistributionTree {
    /// The distribution tree of every class of `octree`, whose entries (by entry id, as given
    /// to [`SampleOctree::build`]) have `areas` and `weights` (`weights` empty: 1 each).
    pub fn from_octree(octree: &SampleOctree, areas: &[f64], weights: &[u64]) -> Self {
        let ids = areas.len();
        let mut t = Self {
            nodes: Vec::with_capacity(octree.nodes.len()),
            roots: octree.roots.clone(),
            location: vec![u32::MAX; ids],
            home: vec![u32::MAX; ids],
            area: areas.to_vec(),
            weight: if weights.is_empty() {
                vec![1; ids]
            } else {
                weights.to_vec()
            },
            extension: octree.config.extension,
        };
        for (i, on) in octree.nodes.iter().enumerate() {
            let own: Vec<u32> = octree.entries[on.own().start as usize..on.own().end as usize].to_vec();
            for &e in &own {
                t.location[e as usize] = i as u32;
                t.home[e as usize] = i as u32;
            }
            t.nodes.push(DynNode {
                cell_min: on.cell_min,
                cell_side: on.cell_side,
                parent: u32::MAX,
                children: on.children(),
                own,
                own_sums: Sums::default(),
                subtree_sums: Sums::default(),
            });
        }
        for i in 0..t.nodes.len() {
            for c in t.nodes[i].children.clone() {
                t.nodes[c as usize].parent = i as u32;
            }
        }
        // Children are stored after their parent: sum from the back.
        for i in (0..t.nodes.len()).rev() {
            t.recompute_own(i);
            t.recompute_subtree(i);
        }
        t
    }

    fn recompute_own(&mut self, n: usize) {
        let node = &self.nodes[n];
        let sums = node.own.iter().fold(Sums::default(), |s, &e| {
            s.add(self.area[e as usize], self.weight[e as usize])
        });
        self.nodes[n].own_sums = sums;
    }

    fn recompute_subtree(&mut self, n: usize) {
        let node = &self.nodes[n];
        let sums = node.children.clone().fold(node.own_sums, |s, c| {
            let child = self.nodes[c as usize].subtree_sums;
            s.add(child.area, child.weight)
        });
        self.nodes[n].subtree_sums = sums;
    }

    /// Recomputes the sums of node `n` and its ancestors, O(height · (own + 8)).
    fn update_path(&mut self, n: u32) {
        self.recompute_own(n as usize);
        let mut m = n;
        while m != u32::MAX {
            self.recompute_subtree(m as usize);
            m = self.nodes[m as usize].parent;
        }
    }

    /// The root of each class (as the octree's).
    pub fn roots(&self) -> &[Option<u32>] {
        &self.roots
    }
    /// Summed area of all classes.
    pub fn total_area(&self) -> f64 {
        self.roots
            .iter()
            .flatten()
            .map(|&r| self.nodes[r as usize].subtree_sums.area)
            .sum()
    }
    /// Summed weight of all classes.
    pub fn total_weight(&self) -> u64 {
        self.roots.iter().flatten().fold(0u64, |a, &r| {
            a.saturating_add(self.nodes[r as usize].subtree_sums.weight)
        })
    }
    /// Summed area and weight of node `n`'s subtree.
    #[inline]
    pub fn subtree_sums(&self, n: u32) -> Sums {
        self.nodes[n as usize].subtree_sums
    }
    /// Summed area and weight of node `n`'s own entries.
    #[inline]
    pub fn own_sums(&self, n: u32) -> Sums {
        self.nodes[n as usize].own_sums
    }
    /// The entries stored at node `n`, sorted by id.
    #[inline]
    pub fn own(&self, n: u32) -> &[u32] {
        &self.nodes[n as usize].own
    }
    /// Number of stored nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }
    /// True when entry `id` is present.
    pub fn contains(&self, id: u32) -> bool {
        self.location.get(id as usize).is_some_and(|&l| l != u32::MAX)
    }
    /// The node that held entry `id` in the static build, if any.
    pub fn home(&self, id: u32) -> Option<u32> {
        self.home.get(id as usize).copied().filter(|&h| h != u32::MAX)
    }
    /// Area and weight of entry `id` (present or not; zero when never seen).
    pub fn entry(&self, id: u32) -> (f64, u64) {
        (
            self.area.get(id as usize).copied().unwrap_or(0.0),
            self.weight.get(id as usize).copied().unwrap_or(0),
        )
    }

    fn check_new(&mut self, id: u32, area: f64) -> Result<(), String> {
        if !(area > 0.0 && area.is_finite()) {
            return Err(format!("entry {id}: area {area} is not positive and finite"));
        }
        if self.nodes.is_empty() {
            return Err("distribution tree without nodes".into());
        }
        if self.location.len() <= id as usize {
            let n = id as usize + 1;
            self.location.resize(n, u32::MAX);
            self.home.resize(n, u32::MAX);
            self.area.resize(n, 0.0);
            self.weight.resize(n, 0);
        }
        if self.location[id as usize] != u32::MAX {
            return Err(format!("entry {id} is already present"));
        }
        Ok(())
    }

    fn place(&mut self, id: u32, n: u32, area: f64, weight: u64) {
        self.area[id as usize] = area;
        self.weight[id as usize] = weight;
        let own = &mut self.nodes[n as usize].own;
        let pos = own.binary_search(&id).unwrap_or_else(|p| p);
        own.insert(pos, id);
        self.location[id as usize] = n;
        self.update_path(n);
    }

    /// Inserts entry `id` with `bounds`, `area` (> 0, finite) and weight 1: descends from the
    /// first class root to the node that stores it by the static rule, then corrects the sums
    /// up to the root, O(height).
    ///
    /// # Errors
    /// A message when the area is not positive and finite, the box is empty, the tree has no
    /// class root, or the id is already present.
    pub fn insert(&mut self, id: u32, bounds: Aabb, area: f64) -> Result<(), String> {
        if bounds.is_empty() {
            return Err(format!("entry {id}: empty bounds"));
        }
        self.check_new(id, area)?;
        let Some(mut n) = self.roots.iter().flatten().next().copied() else {
            return Err("distribution tree without root".into());
        };
        'descend: loop {
            for c in self.nodes[n as usize].children.clone() {
                let cn = &self.nodes[c as usize];
                if contains(&extended(cn.cell_min, cn.cell_side, self.extension), &bounds) {
                    n = c;
                    continue 'descend;
                }
            }
            break;
        }
        self.place(id, n, area, 1);
        Ok(())
    }

    /// Inserts entry `id` at node `node` with `area` (> 0, finite) and `weight`, O(height).
    ///
    /// # Errors
    /// A message when the area is not positive and finite, the node does not exist, or the id
    /// is already present.
    pub fn insert_at(&mut self, id: u32, node: u32, area: f64, weight: u64) -> Result<(), String> {
        self.check_new(id, area)?;
        if node as usize >= self.nodes.len() {
            return Err(format!("entry {id}: no node {node}"));
        }
        self.place(id, node, area, weight);
        Ok(())
    }

    /// Removes entry `id`, correcting the sums up to the root, O(height).
    ///
    /// # Errors
    /// A message when the entry is absent.
    pub fn remove(&mut self, id: u32) -> Result<(), String> {
        if !self.contains(id) {
            return Err(format!("entry {id} is not present"));
        }
        let n = self.location[id as usize];
        let own = &mut self.nodes[n as usize].own;
        if let Ok(pos) = own.binary_search(&id) {
            own.remove(pos);
        }
        self.location[id as usize] = u32::MAX;
        self.update_path(n);
        Ok(())
    }

    /// Changes the area and weight of entry `id` (present or not), O(height) when present.
    ///
    /// # Errors
    /// A message when the area is negative or not finite.
    pub fn set_entry(&mut self, id: u32, area: f64, weight: u64) -> Result<(), String> {
        if !(area >= 0.0 && area.is_finite()) {
            return Err(format!("entry {id}: area {area} is negative or not finite"));
        }
        if (id as usize) < self.area.len() {
            self.area[id as usize] = area;
            self.weight[id as usize] = weight;
            if self.contains(id) {
                self.update_path(self.location[id as usize]);
            }
        }
        Ok(())
    }

    /// §5.4: an entry of the subtree of `node` chosen with probability proportional to its
    /// area, from `u ∈ [0, 1)`: descend, choosing the own list or a child by summed areas.
    /// `None` when the subtree has no area.
    pub fn sample(&self, node: u32, u: f64) -> Option<u32> {
        let n = self.nodes.get(node as usize)?;
        if n.subtree_sums.area <= 0.0 {
            return None;
        }
        Some(self.descend(node, u * n.subtree_sums.area))
    }

    /// An entry stored at `node` itself (not below), chosen by area from `u ∈ [0, 1)`.
    pub fn sample_own(&self, node: u32, u: f64) -> Option<u32> {
        let n = self.nodes.get(node as usize)?;
        let mut r = u * n.own_sums.area;
        let mut last = None;
        for &e in &n.own {
            let a = self.area[e as usize];
            if a > 0.0 {
                if r < a {
                    return Some(e);
                }
                r -= a;
                last = Some(e);
            }
        }
        last
    }

    /// An entry of the whole tree (every class), chosen by area from `u ∈ [0, 1)`.
    pub fn sample_all(&self, u: f64) -> Option<u32> {
        let total = self.total_area();
        if total <= 0.0 {
            return None;
        }
        let mut r = u * total;
        let mut last = None;
        for &root in self.roots.iter().flatten() {
            let a = self.nodes[root as usize].subtree_sums.area;
            if a > 0.0 {
                if r < a {
                    return Some(self.descend(root, r));
                }
                r -= a;
                last = Some((root, a));
            }
        }
        // Rounding left r at the end: the end of the last class with area.
        last.map(|(root, a)| self.descend(root, a))
    }

    fn descend(&self, node: u32, mut r: f64) -> u32 {
        let mut n = node as usize;
        loop {
            let node = &self.nodes[n];
            let mut last = None;
            for &e in &node.own {
                let a = self.area[e as usize];
                if a > 0.0 {
                    if r < a {
                        return e;
                    }
                    r -= a;
                    last = Some(e);
                }
            }
            let mut next = None;
            for c in node.children.clone() {
                let a = self.nodes[c as usize].subtree_sums.area;
                if a > 0.0 {
                    if r < a {
                        next = Some(c as usize);
                        break;
                    }
                    r -= a;
                    next = Some(c as usize);
                }
            }
            match (next, last) {
                (Some(c), _) => n = c,
                // Rounding left r at the end: the last own entry.
                (None, Some(e)) => return e,
                // Only reachable through rounding into an empty subtree: its parent's area
                // was positive, so some entry exists; take the first own entry found upwards.
                (None, None) => return self.nodes[n].own.first().copied().unwrap_or(0),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_triangles(n: usize, seed: u64) -> (Vec<Aabb>, Vec<f64>) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut boxes = Vec::new();
        let mut areas = Vec::new();
        for _ in 0..n {
            let c = Vec3::new(rng.random::<f32>(), rng.random::<f32>(), rng.random::<f32>()) * 100.0;
            let s = rng.random::<f32>() * 2.0 + 0.01;
            boxes.push(Aabb::new(c - Vec3::splat(s), c + Vec3::splat(s)));
            areas.push((s * s) as f64 * rng.random_range(0.5..1.5));
        }
        (boxes, areas)
    }

    #[test]
    fn sections_partition_the_list_and_entries_fit_their_extended_cells() {
        let (boxes, areas) = random_triangles(5000, 1);
        let classes = vec![0; boxes.len()];
        let t = SampleOctree::build(&boxes, &areas, &classes, 1, &SampleOctreeConfig::default())
            .expect("5000 random triangles build");
        assert_eq!(t.entries().len(), 5000);
        let mut seen = vec![false; 5000];
        for &e in t.entries() {
            assert!(!seen[e as usize]);
            seen[e as usize] = true;
        }
        let ext = t.config().extension;
        for n in t.nodes() {
            // Children's sections tile first..own_first in order.
            let mut p = n.first;
            for c in n.children() {
                let cn = &t.nodes()[c as usize];
                assert_eq!(cn.first, p);
                p = cn.end;
                let e = extended(cn.cell_min, cn.cell_side, ext);
                for q in cn.section() {
                    assert!(contains(&e, &boxes[t.entries()[q as usize] as usize]));
                }
            }
            assert_eq!(p, n.own_first);
            // Shortcuts: no stored inner node with one child and no own entries.
            assert!(!(n.child_count == 1 && n.own_first == n.end));
            if n.is_leaf() {
                assert!(n.end - n.first <= 32 || n.first == n.own_first);
            }
        }
        let root = t.nodes()[t.roots()[0].expect("5000 entries of class 0 have a root") as usize];
        assert_eq!(root.section(), 0..5000);
        assert!((t.area(root.section()) - areas.iter().sum::<f64>()).abs() < 1e-6 * t.total_area());
    }

    #[test]
    fn pick_matches_exhaustive_inversion() {
        let (boxes, mut areas) = random_triangles(300, 2);
        areas[7] = 0.0; // never sampled
        let classes: Vec<u32> = (0..300).map(|i| (i % 3) as u32).collect();
        let t = SampleOctree::build(&boxes, &areas, &classes, 3, &SampleOctreeConfig::default())
            .expect("300 random triangles in three classes build");
        assert_eq!(t.entries().len(), 299);
        for n in t.nodes() {
            let r = n.section();
            for k in 0..50 {
                let u = k as f64 / 50.0;
                let p = t.pick(r.clone(), u);
                // Oracle: linear scan of the cumulative sums.
                let target = u * t.area(r.clone());
                let mut acc = 0.0;
                let mut want = r.end - 1;
                for q in r.clone() {
                    acc += areas[t.entries()[q as usize] as usize];
                    if acc > target + 1e-9 * t.total_area() {
                        want = q;
                        break;
                    }
                }
                assert_eq!(p, want);
            }
            assert!(t.pick(r.clone(), 0.999_999_999_999) < r.end);
        }
    }

    #[test]
    fn coincident_entries_and_empty_input_terminate() {
        let boxes = vec![Aabb::new(Vec3::ONE, Vec3::ONE); 1000];
        let areas = vec![1.0; 1000];
        let build = |boxes: &[Aabb], areas: &[f64], classes: &[u32], class_count: usize| {
            SampleOctree::build(boxes, areas, classes, class_count, &SampleOctreeConfig::default())
                .expect("coincident or no entries build")
        };
        let t = build(&boxes, &areas, &[0; 1000], 1);
        assert_eq!(t.entries().len(), 1000);
        let e = build(&[], &[], &[], 2);
        assert_eq!(e.roots(), &[None, None]);
        let nan = build(&[Aabb::new(Vec3::NAN, Vec3::NAN)], &[1.0], &[0], 1);
        assert!(nan.entries().is_empty());
    }

    /// A leaf size the build used to clamp, and absurd extensions and depths, are errors naming
    /// the field; the deepest limit builds.
    #[test]
    fn bad_configs_are_errors() {
        let (boxes, areas) = random_triangles(100, 6);
        let d = SampleOctreeConfig::default();
        for (bad, field) in [
            (
                SampleOctreeConfig {
                    leaf_size: 0,
                    ..d.clone()
                },
                "leaf_size",
            ),
            (
                SampleOctreeConfig {
                    extension: -0.25,
                    ..d.clone()
                },
                "extension",
            ),
            (
                SampleOctreeConfig {
                    extension: f32::INFINITY,
                    ..d.clone()
                },
                "extension",
            ),
            (
                SampleOctreeConfig {
                    max_depth: cell::MAX_OCTREE_DEPTH + 1,
                    ..d.clone()
                },
                "max_depth",
            ),
        ] {
            let e = SampleOctree::build(&boxes, &areas, &[0; 100], 1, &bad).unwrap_err();
            assert_eq!(e.field, field);
        }
        let deepest = SampleOctreeConfig {
            max_depth: cell::MAX_OCTREE_DEPTH,
            ..d
        };
        assert_eq!(d.max_depth, cell::MAX_OCTREE_DEPTH);
        assert!(SampleOctree::build(&boxes, &areas, &[0; 100], 1, &deepest).is_ok());
    }

    fn histogram(t: &DistributionTree, n: usize, bins: usize, seed: u64) -> Vec<u32> {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut h = vec![0u32; bins];
        for _ in 0..n {
            h[t.sample(0, rng.random::<f64>()).expect("the tree has positive area") as usize] += 1;
        }
        h
    }

    /// Pearson chi-square of `h` against probabilities proportional to `areas`.
    fn chi_square(h: &[u32], areas: &[f64]) -> f64 {
        let n: u32 = h.iter().sum();
        let total: f64 = areas.iter().sum();
        h.iter()
            .zip(areas)
            .filter(|(_, &a)| a > 0.0)
            .map(|(&c, &a)| {
                let e = n as f64 * a / total;
                (c as f64 - e).powi(2) / e
            })
            .sum()
    }

    #[test]
    fn distribution_tree_insert_then_remove_restores_the_distribution() {
        let (boxes, areas) = random_triangles(400, 3);
        let (extra_boxes, extra_areas) = random_triangles(100, 4);
        let t = SampleOctree::build(
            &boxes,
            &areas,
            &[0; 400],
            1,
            &SampleOctreeConfig {
                leaf_size: 8,
                ..Default::default()
            },
        )
        .expect("400 random triangles build");
        let mut d = DistributionTree::from_octree(&t, &areas, &[]);
        let before_total = d.total_area();
        let samples = 400_000;
        let h0 = histogram(&d, samples, 500, 9);
        // 399 degrees of freedom: mean 399, sd ≈ 28; 550 is > 5 sd.
        assert!(chi_square(&h0[..400], &areas) < 550.0);
        for i in 0..100 {
            d.insert(400 + i, extra_boxes[i as usize], extra_areas[i as usize])
                .expect("a new id with a non-empty box inserts");
        }
        let mut all = areas.clone();
        all.extend_from_slice(&extra_areas);
        let h1 = histogram(&d, samples, 500, 10);
        assert!(chi_square(&h1, &all) < 650.0);
        assert!(h1[400..].iter().sum::<u32>() > 0);
        for i in 0..100 {
            d.remove(400 + i).expect("an inserted entry is present");
        }
        assert!((d.total_area() - before_total).abs() < 1e-9 * before_total);
        let h2 = histogram(&d, samples, 500, 9);
        assert!(h2[400..].iter().all(|&c| c == 0));
        assert!(chi_square(&h2[..400], &areas) < 550.0);
        // History does not matter: removing and re-inserting static entries at their home
        // nodes restores the sums bit for bit, hence the very same samples for a seed.
        let sums = |d: &DistributionTree| {
            (0..d.node_count() as u32)
                .map(|n| d.subtree_sums(n).area.to_bits())
                .collect::<Vec<_>>()
        };
        let before = sums(&d);
        let h_before = histogram(&d, 10_000, 500, 11);
        for i in (0..400).step_by(7) {
            d.remove(i).expect("a static entry is present");
        }
        assert!(sums(&d) != before);
        for i in (0..400).step_by(7).rev() {
            let home = d.home(i).expect("a removed static entry keeps its home node");
            d.insert_at(i, home, areas[i as usize], 1)
                .expect("an absent entry reinserts at its home node");
        }
        assert_eq!(sums(&d), before);
        assert_eq!(histogram(&d, 10_000, 500, 11), h_before);
        assert!(d.remove(450).is_err());
        assert!(d.insert(3, boxes[3], 1.0).is_err());
        assert!(d.insert(999, boxes[3], 0.0).is_err());
    }
}
