//! Front-to-back ray traversal of an [`Octree`], for rays with a thickness.
//!
//! # References
//! - Han & Zeiger, "The Local Z-Buffering Rendering", §III.A (a ray path: the leaves a ray
//!   traverses until its visibility is resolved) and §III.D (coherence-based ray–octree
//!   traversal: a ray starts from what its neighbour found).
//!
//! A [`FatRay`] is a cone around `origin + t · direction`: at parameter `t` its radius is
//! `spread · t + margin` (object units). Boxes are grown by the radius at their far side before
//! the slab test, so a leaf is visited whenever any point of it lies within the cone. This is what
//! makes a ray path conservative against the rasterizer, whose coverage is decided on vertices
//! snapped to 1/256 pixel rather than on the exact ray through the pixel centre.
//!
//! Children are visited nearest entry first; a node whose entry lies beyond the current bound
//! `t_limit` is skipped, and the leaf callback may lower the bound. Correctness never depends on
//! the order, only cost does: every leaf whose grown box the cone enters before the final bound
//! is visited.
//!
//! Coherence (§III.D), deviation: instead of restarting the descent at a node found by the
//! neighbouring ray (which would miss the leaves in front of that node, and the path must hold
//! all of them), a caller passes the bound its neighbour's first hit gives
//! ([`traverse`]'s `t_limit`): the descent then prunes everything behind it from the start.

use crate::octree::{Octree, MAX_OCTREE_DEPTH};
use occult_core::{Aabb, Vec3};

/// A ray with a thickness growing linearly with `t` (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FatRay {
    /// Origin.
    pub origin: Vec3,
    /// Direction (any length; `t` is in its units).
    pub direction: Vec3,
    inv_direction: Vec3,
    inv_length: f32,
    /// Radius per unit of `t`.
    pub spread: f32,
    /// Radius at `t = 0`.
    pub margin: f32,
}

impl FatRay {
    /// A cone of radius `spread · t + margin` around the ray.
    pub fn new(origin: Vec3, direction: Vec3, spread: f32, margin: f32) -> Self {
        Self {
            origin,
            direction,
            inv_direction: direction.recip(),
            inv_length: 1.0 / direction.length(),
            spread,
            margin,
        }
    }

    /// Entry and exit parameters (entry clamped at 0) of `b` grown by the cone's radius at the
    /// box's far side; `None` when the cone misses it.
    #[inline]
    pub fn enter(&self, b: &Aabb) -> Option<(f32, f32)> {
        let (lo, hi) = if self.spread == 0.0 && self.margin == 0.0 {
            (b.min, b.max)
        } else {
            // The farthest point of the box is at most |c - o| + |h| away; the 1-norms bound
            // the Euclidean ones from above without a square root.
            let c = b.center();
            let h = b.half_extent();
            let far_t = ((c - self.origin).abs().element_sum() + h.element_sum()) * self.inv_length;
            let grow = Vec3::splat(self.spread * far_t + self.margin);
            (b.min - grow, b.max + grow)
        };
        let t0 = (lo - self.origin) * self.inv_direction;
        let t1 = (hi - self.origin) * self.inv_direction;
        // NaN (0 · ∞) only when the origin lies on a slab plane of a zero direction component:
        // f32::min/max then ignore it, which keeps the test conservative.
        let near = t0.min(t1).max_element().max(0.0);
        let far = t0.max(t1).min_element();
        (near <= far).then_some((near, far))
    }
}

/// Counts of one or more traversals (pbrt style: the algorithm counts as it goes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalCounters {
    /// Nodes taken from the stack and processed (internal nodes expanded, leaves handed over).
    pub nodes_visited: u64,
    /// Non-empty leaves handed to the callback.
    pub leaves_visited: u64,
}

/// Visits the leaves of `octree` that `ray` enters before `*t_limit`, nearest entry first.
/// `leaf(node_index, t_enter, t_exit, t_limit)` sees each non-empty leaf once and may lower
/// `*t_limit`; leaves whose entry lies beyond the bound at the time they come up are skipped.
pub fn traverse(
    octree: &Octree,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    mut leaf: impl FnMut(u32, f32, f32, &mut f32),
) {
    let nodes = octree.nodes();
    let Some(root) = nodes.first() else { return };
    let Some((t0, _)) = ray.enter(&root.bounds) else {
        return;
    };
    const STACK: usize = 8 * MAX_OCTREE_DEPTH as usize + 8;
    let mut stack = [(0u32, 0f32); STACK];
    stack[0] = (0, t0);
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let (index, t_enter) = stack[top];
        if t_enter > *t_limit {
            continue;
        }
        counters.nodes_visited += 1;
        let node = &nodes[index as usize];
        if node.is_leaf() {
            if node.count > 0 {
                counters.leaves_visited += 1;
                // The exit is recomputed for the leaf only (internal nodes never need it).
                let t_exit = ray.enter(&node.bounds).map_or(t_enter, |(_, x)| x);
                leaf(index, t_enter, t_exit, t_limit);
            }
            continue;
        }
        // Children that the cone enters, sorted by entry, pushed farthest first.
        let mut kids = [(0u32, 0f32); 8];
        let mut k = 0;
        for c in node.children() {
            let child = &nodes[c as usize];
            if child.is_leaf() && child.count == 0 {
                continue;
            }
            if let Some((e, _)) = ray.enter(&child.bounds) {
                if e <= *t_limit {
                    let mut j = k;
                    while j > 0 && kids[j - 1].1 < e {
                        kids[j] = kids[j - 1];
                        j -= 1;
                    }
                    kids[j] = (c, e);
                    k += 1;
                }
            }
        }
        // kids is sorted by decreasing entry: push in that order so the nearest pops first.
        stack[top..top + k].copy_from_slice(&kids[..k]);
        top += k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::octree::OctreeConfig;
    use occult_core::{intersect_ray_triangle, Ray};

    fn soup(n: usize, seed: u64) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut s = seed;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut p = Vec::new();
        let mut t = Vec::new();
        for i in 0..n as u32 {
            let c = Vec3::new(rnd(), rnd(), rnd()) * 10.0;
            for _ in 0..3 {
                p.push(c + (Vec3::new(rnd(), rnd(), rnd()) - 0.5) * 1.5);
            }
            t.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        (p, t)
    }

    /// Oracle: the nearest hit by linear scan, against the nearest hit through the traversal
    /// (bound lowered at each hit), over many random rays.
    #[test]
    fn nearest_hit_matches_linear_scan() {
        let (p, t) = soup(400, 7);
        let cfg = OctreeConfig {
            max_depth: 6,
            max_leaf_size: 8,
        };
        let o = Octree::build_triangles(&p, &t, cfg).unwrap();
        let mut s = 99u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut counters = TraversalCounters::default();
        for _ in 0..500 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 30.0 - 10.0;
            let dir = Vec3::new(rnd(), rnd(), rnd()) * 10.0 + 0.0 - origin * 0.2;
            let ray = Ray::new(origin, dir);
            let tri = |i: u32| t[i as usize].map(|v| p[v as usize]);
            let brute = (0..t.len() as u32)
                .filter_map(|i| {
                    let [a, b, c] = tri(i);
                    intersect_ray_triangle(&ray, a, b, c).map(|h| h.t)
                })
                .fold(f32::INFINITY, f32::min);
            let fat = FatRay::new(origin, dir, 0.0, 0.0);
            let mut limit = f32::INFINITY;
            traverse(&o, &fat, &mut limit, &mut counters, |leaf, _, _, limit| {
                for &i in o.leaf_primitives(leaf) {
                    let [a, b, c] = tri(i);
                    if let Some(h) = intersect_ray_triangle(&ray, a, b, c) {
                        *limit = limit.min(h.t);
                    }
                }
            });
            assert_eq!(limit, brute);
        }
        assert!(counters.nodes_visited > 0);
    }

    /// Every leaf a cone touches before the bound is visited: compare with all leaves whose
    /// grown box the cone enters (linear scan over leaves).
    #[test]
    fn cone_visits_every_leaf_it_touches() {
        let (p, t) = soup(300, 3);
        let o = Octree::build_triangles(
            &p,
            &t,
            OctreeConfig {
                max_depth: 5,
                max_leaf_size: 4,
            },
        )
        .unwrap();
        for k in 0..50 {
            let origin = Vec3::new(-5.0, k as f32 * 0.3, 2.0);
            let ray = FatRay::new(origin, Vec3::new(1.0, 0.05, 0.1), 0.01, 0.001);
            let bound = 12.0;
            let mut visited = vec![];
            let mut limit = bound;
            traverse(&o, &ray, &mut limit, &mut TraversalCounters::default(), |l, _, _, _| {
                visited.push(l)
            });
            visited.sort_unstable();
            let expect: Vec<u32> = (0..o.nodes().len() as u32)
                .filter(|&i| {
                    let n = &o.nodes()[i as usize];
                    n.is_leaf() && n.count > 0 && ray.enter(&n.bounds).is_some_and(|(e, _)| e <= bound)
                })
                .collect();
            // Pruning on ancestors may only keep leaves the scan keeps (ancestors hold them).
            assert_eq!(visited, expect);
        }
    }

    #[test]
    fn empty_tree_and_missing_ray() {
        let o = Octree::default();
        let mut limit = f32::INFINITY;
        traverse(
            &o,
            &FatRay::new(Vec3::ZERO, Vec3::X, 0.0, 0.0),
            &mut limit,
            &mut TraversalCounters::default(),
            |_, _, _, _| panic!("no leaf"),
        );
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert!(FatRay::new(Vec3::new(0.5, 0.5, 5.0), Vec3::Z, 0.0, 0.0)
            .enter(&b)
            .is_none());
        assert!(FatRay::new(Vec3::new(1.05, 0.5, 5.0), -Vec3::Z, 0.0, 0.1)
            .enter(&b)
            .is_some());
    }
}
