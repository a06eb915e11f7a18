//! An 8-wide bounding volume hierarchy over a mesh's triangles for fat rays ([`RayBvh`]), and
//! its front-to-back traversal ([`traverse_bvh`]): the ray caster of local z-buffering when
//! `caster=bvh` (a deviation from the paper, whose rays walk the octree of §II.A).
//!
//! # References
//! - Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies", IEEE RT 2007:
//!   binned surface-area-heuristic build (16 bins per axis, the three axes tried).
//! - Wald, Benthin & Boulos, "Getting Rid of Packets: Efficient SIMD Single-Ray Traversal using
//!   Multi-branching BVHs", IEEE RT 2008, and Dammertz et al., "Shallow Bounding Volume
//!   Hierarchies for Fast SIMD Ray Tracing of Incoherent Rays", EGSR 2008: a binary BVH
//!   collapsed into wide nodes by opening the child of largest area until 8, the 8 children's
//!   boxes stored as structure of arrays and tested in one SIMD pass.
//!
//! One reference per triangle (no splitting): a triangle lies in exactly one leaf, and a leaf's
//! triangles are contiguous in [`RayBvh::triangles`]' order, so the caller stores them in that
//! order (as [`crate::LeafTriangle`]s) and tests a leaf with [`crate::ShearedRay::intersect8`]
//! in one call. Leaves hold at most [`MAX_BVH_LEAF`] triangles.
//!
//! A [`FatRay`] enters a child when it enters the child's box grown by the cone's radius at the
//! box's far side, exactly [`FatRay::enter`]'s rule, applied per child: every leaf whose grown
//! box the cone enters before the final bound is handed over (each box holds its children's,
//! so an ancestor's grown box is entered no later than its descendant's).

use crate::raycast::TraversalCounters;
use crate::{prefetch_triangles, FatRay, LeafTriangle};
use occult_core::simd::{Avx2, Isa};
#[cfg(target_arch = "x86_64")]
use occult_core::simd::{F32x8, M32x8};
use occult_core::{Aabb, Vec3};

/// Most triangles in a leaf: the lanes of [`crate::ShearedRay::intersect8`].
pub const MAX_BVH_LEAF: usize = 8;
/// Most triangles one [`RayBvh`] may hold (a leaf's first slot takes 27 bits of its code).
pub const MAX_BVH_TRIANGLES: usize = (1 << 27) - 1;
/// Binary depth from which a node is split at its middle rather than by the heuristic: bounds
/// the tree's depth (and so the traversal stack) whatever the input.
const SAH_DEPTH: u32 = 48;
/// Entries of the traversal stack: a wide level pops one entry and pushes at most 8, and the
/// tree is at most `SAH_DEPTH + 32` levels deep.
pub(crate) const STACK: usize = 7 * (SAH_DEPTH as usize + 32) + 8;
/// Bins per axis of the build.
const BINS: usize = 16;
/// A child code's leaf flag.
const LEAF: u32 = 1 << 31;

/// Why a [`RayBvh`] was not built.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RayBvhError {
    /// A leaf size outside `1..=`[`MAX_BVH_LEAF`].
    #[error("max_leaf_size={0} is not in 1..={MAX_BVH_LEAF}")]
    BadLeafSize(usize),
    /// More triangles than [`MAX_BVH_TRIANGLES`].
    #[error("{0} triangles exceed the {MAX_BVH_TRIANGLES} a ray BVH holds")]
    TooLarge(usize),
}

/// A wide node: its (up to) 8 children's boxes as structure of arrays, and what each child is.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct RayBvhNode {
    /// Per axis, the children's lower corners (lane = child).
    pub lo: [[f32; 8]; 3],
    /// Per axis, the children's upper corners.
    pub hi: [[f32; 8]; 3],
    /// Per child: a node index, or a leaf code ([`RayBvh::leaf_range`]).
    pub child: [u32; 8],
    /// Bit `i` set when child `i` exists.
    pub valid: u32,
}

impl RayBvhNode {
    /// The box of child `lane`.
    #[inline]
    pub fn child_bounds(&self, lane: usize) -> Aabb {
        Aabb::new(
            Vec3::new(self.lo[0][lane], self.lo[1][lane], self.lo[2][lane]),
            Vec3::new(self.hi[0][lane], self.hi[1][lane], self.hi[2][lane]),
        )
    }
}

/// Termination of the build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RayBvhConfig {
    /// Most triangles per leaf, `1..=`[`MAX_BVH_LEAF`].
    pub max_leaf_size: usize,
}

/// An 8-wide BVH over triangles (see the module doc).
#[derive(Clone, Debug, Default)]
pub struct RayBvh {
    nodes: Vec<RayBvhNode>,
    /// Per node, its parent's index (the root's: itself).
    parents: Vec<u32>,
    order: Vec<u32>,
    /// The triangles as the ray caster reads them, in the order's slots
    /// ([`RayBvh::attach_triangles`]); prefetched when a leaf is pushed.
    tris: Vec<LeafTriangle>,
    bounds: Aabb,
}

/// A node of the binary build.
struct Binary {
    bounds: Aabb,
    /// Leaf: `(start, count)` in the order; internal: `(left, right)` node indices.
    a: u32,
    b: u32,
    leaf: bool,
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    centroids: &'a [Vec3],
    max_leaf: usize,
}

/// Subtrees over more triangles than this build their two halves in parallel.
const PARALLEL: usize = 1 << 14;

impl Builder<'_> {
    /// Builds the subtree over `order` (slots `offset..` of the whole order) into `out`;
    /// returns its node index.
    fn build(&self, order: &mut [u32], offset: usize, depth: u32, out: &mut Vec<Binary>) -> u32 {
        let bounds = order.iter().fold(Aabb::EMPTY, |a, &t| a.union(self.boxes[t as usize]));
        let n = order.len();
        let index = out.len() as u32;
        out.push(Binary {
            bounds,
            a: offset as u32,
            b: n as u32,
            leaf: true,
        });
        // A leaf's cost, one eight-lane test ([`blocks`]), never exceeds a split's (a node visit
        // plus its sides' tests): every node of at most `max_leaf` triangles is a leaf. The
        // heuristic chooses among splits above that size.
        if n <= self.max_leaf {
            return index;
        }
        let cb = order
            .iter()
            .fold(Aabb::EMPTY, |a, &t| a.including(self.centroids[t as usize]));
        let split = if depth < SAH_DEPTH {
            self.sah_split(order, &cb, &bounds)
        } else {
            None
        };
        let c = self.centroids;
        let mid = match split {
            Some((axis, bin)) => {
                let (lo, scale) = bin_map(&cb, axis);
                let mut i = 0;
                for j in 0..n {
                    if bin_of(c[order[j] as usize][axis], lo, scale) <= bin {
                        order.swap(i, j);
                        i += 1;
                    }
                }
                i
            }
            None => {
                // No separating bin (coincident centroids) or too deep: the middle of the
                // order along the longest centroid axis.
                let axis = cb.size().max_position();
                order.select_nth_unstable_by(n / 2, |&x, &y| c[x as usize][axis].total_cmp(&c[y as usize][axis]));
                n / 2
            }
        };
        let (lo, hi) = order.split_at_mut(mid);
        let (left, right) = if n > PARALLEL {
            let (l, r) = rayon::join(
                || {
                    let mut v = Vec::new();
                    self.build(lo, offset, depth + 1, &mut v);
                    v
                },
                || {
                    let mut v = Vec::new();
                    self.build(hi, offset + mid, depth + 1, &mut v);
                    v
                },
            );
            (append(out, l), append(out, r))
        } else {
            (
                self.build(lo, offset, depth + 1, out),
                self.build(hi, offset + mid, depth + 1, out),
            )
        };
        let node = &mut out[index as usize];
        node.a = left;
        node.b = right;
        node.leaf = false;
        index
    }

    /// The best binned split `(axis, last bin of the left side)` by its cost relative to the
    /// node's area, or `None` when no bin separates the centroids.
    fn sah_split(&self, order: &[u32], cb: &Aabb, bounds: &Aabb) -> Option<(usize, usize)> {
        let area = bounds.surface_area().max(f32::MIN_POSITIVE);
        let mut best: Option<(usize, usize, f32)> = None;
        for axis in 0..3 {
            if cb.size()[axis] <= 0.0 {
                continue;
            }
            let (lo, scale) = bin_map(cb, axis);
            let mut count = [0u32; BINS];
            let mut bb = [Aabb::EMPTY; BINS];
            for &t in order {
                let b = bin_of(self.centroids[t as usize][axis], lo, scale);
                count[b] += 1;
                bb[b] = bb[b].union(self.boxes[t as usize]);
            }
            // Right sides swept from the top.
            let mut right_area = [0f32; BINS];
            let mut right_count = [0u32; BINS];
            let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
            for k in (1..BINS).rev() {
                acc = acc.union(bb[k]);
                cnt += count[k];
                right_area[k] = acc.surface_area();
                right_count[k] = cnt;
            }
            let (mut acc, mut cnt) = (Aabb::EMPTY, 0);
            for k in 0..BINS - 1 {
                acc = acc.union(bb[k]);
                cnt += count[k];
                let rc = right_count[k + 1];
                if cnt == 0 || rc == 0 {
                    continue;
                }
                let cost = (acc.surface_area() * blocks(cnt) + right_area[k + 1] * blocks(rc)) / area;
                if best.is_none_or(|(_, _, c)| cost < c) {
                    best = Some((axis, k, cost));
                }
            }
        }
        best.map(|(axis, bin, _)| (axis, bin))
    }
}

/// The heuristic's cost of testing `n` triangles: the eight-lane tests they take
/// ([`crate::ShearedRay::intersect8`] tests a leaf's triangles in one pass of eight lanes, as a
/// node's eight children are tested in one), each as costly as a node visit. Counting
/// triangles one by one instead made leaves of two triangles on average, most lanes of each
/// test idle (Wald et al., "Embree: a kernel framework for efficient CPU ray tracing", 2014,
/// count leaf primitives in blocks of their SIMD width the same way).
#[inline]
fn blocks(n: u32) -> f32 {
    n.div_ceil(MAX_BVH_LEAF as u32) as f32
}

/// Appends subtree `sub` (root at its index 0) to `out`, its node links shifted; returns the
/// subtree's root index in `out`.
fn append(out: &mut Vec<Binary>, sub: Vec<Binary>) -> u32 {
    let shift = out.len() as u32;
    out.extend(sub.into_iter().map(|mut b| {
        if !b.leaf {
            b.a += shift;
            b.b += shift;
        }
        b
    }));
    shift
}

/// The bin map of axis `axis` over centroid bounds `cb`: `(lower end, bins per unit)`.
#[inline]
fn bin_map(cb: &Aabb, axis: usize) -> (f32, f32) {
    let extent = cb.size()[axis];
    (cb.min[axis], BINS as f32 * (1.0 - 1e-6) / extent)
}

#[inline]
fn bin_of(v: f32, lo: f32, scale: f32) -> usize {
    (((v - lo) * scale) as usize).min(BINS - 1)
}

impl RayBvh {
    /// Builds the BVH of triangles `triangles` (corner indices into `positions`).
    ///
    /// # Errors
    /// [`RayBvhError`] for a leaf size out of range or too many triangles.
    pub fn build_triangles(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        config: RayBvhConfig,
    ) -> Result<Self, RayBvhError> {
        if !(1..=MAX_BVH_LEAF).contains(&config.max_leaf_size) {
            return Err(RayBvhError::BadLeafSize(config.max_leaf_size));
        }
        if triangles.len() > MAX_BVH_TRIANGLES {
            return Err(RayBvhError::TooLarge(triangles.len()));
        }
        if triangles.is_empty() {
            return Ok(Self::default());
        }
        let boxes: Vec<Aabb> = triangles
            .iter()
            .map(|t| Aabb::from_points(t.map(|v| positions[v as usize])))
            .collect();
        let centroids: Vec<Vec3> = boxes.iter().map(Aabb::center).collect();
        let b = Builder {
            boxes: &boxes,
            centroids: &centroids,
            max_leaf: config.max_leaf_size,
        };
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        let mut binary = Vec::with_capacity(2 * triangles.len() / config.max_leaf_size + 1);
        let root = b.build(&mut order, 0, 0, &mut binary);
        // Rays read nodes at scattered places: on huge pages, a node's first read is one miss,
        // not a page walk and a miss. A wide node takes at least one internal binary node.
        let mut nodes = occult_core::memory::huge_page_vec(binary.len() / 2 + 1);
        collapse(&binary, root, &mut nodes);
        let mut parents = vec![0u32; nodes.len()];
        for (i, n) in nodes.iter().enumerate() {
            for lane in 0..8 {
                if n.valid & (1 << lane) != 0 && !Self::is_leaf(n.child[lane]) {
                    parents[n.child[lane] as usize] = i as u32;
                }
            }
        }
        Ok(Self {
            bounds: binary[root as usize].bounds,
            nodes,
            parents,
            order,
            tris: Vec::new(),
        })
    }

    /// The wide nodes; the root is node 0 (absent when there is no triangle).
    pub fn nodes(&self) -> &[RayBvhNode] {
        &self.nodes
    }

    /// Keeps `tris`, triangle `slot` of [`RayBvh::triangles`] at index `slot`, for
    /// [`RayBvh::leaf_triangles`]; the traversal then asks for a leaf's triangles as it pushes
    /// the leaf, so that the misses of the leaves met at one node overlap. Rays read them at
    /// scattered places, so they are best on huge pages ([`occult_core::memory::huge_page_vec`]).
    ///
    /// # Panics
    /// When `tris` does not hold one triangle per slot.
    pub fn attach_triangles(&mut self, tris: Vec<LeafTriangle>) {
        assert_eq!(tris.len(), self.order.len(), "one triangle per slot");
        self.tris = tris;
    }

    /// The attached triangles of leaf `code` ([`RayBvh::attach_triangles`]; empty when none).
    #[inline]
    pub fn leaf_triangles(&self, code: u32) -> &[LeafTriangle] {
        self.tris.get(Self::leaf_range(code)).unwrap_or(&[])
    }

    /// The parent of node `node` (the root's is the root).
    #[inline]
    pub fn parent(&self, node: u32) -> u32 {
        self.parents[node as usize]
    }

    /// The triangles in leaf order: a leaf's triangles are [`RayBvh::leaf_range`] of it.
    pub fn triangles(&self) -> &[u32] {
        &self.order
    }

    /// The slots of [`RayBvh::triangles`] a leaf code names.
    #[inline]
    pub fn leaf_range(code: u32) -> std::ops::Range<usize> {
        let start = ((code & !LEAF) >> 4) as usize;
        start..start + (code & 15) as usize + 1
    }

    /// True when child code `code` names a leaf.
    #[inline]
    pub fn is_leaf(code: u32) -> bool {
        code & LEAF != 0
    }

    /// Every leaf code, with its box.
    pub fn leaves(&self) -> impl Iterator<Item = (u32, Aabb)> + '_ {
        self.nodes.iter().flat_map(|n| {
            (0..8)
                .filter(move |&i| n.valid & (1 << i) != 0 && Self::is_leaf(n.child[i]))
                .map(move |i| (n.child[i], n.child_bounds(i)))
        })
    }

    /// The triangles' bounds.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Heap bytes.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<RayBvhNode>()
            + (self.order.capacity() + self.parents.capacity()) * 4
            + self.tris.capacity() * std::mem::size_of::<LeafTriangle>()
    }

    /// Sorts each leaf's triangles by `key`, largest first (before triangles are attached).
    pub fn sort_leaves_by_key_descending(&mut self, key: impl Fn(u32) -> f32) {
        debug_assert!(self.tris.is_empty(), "sorted before triangles are attached");
        let codes: Vec<u32> = self.leaves().map(|(c, _)| c).collect();
        for code in codes {
            self.order[Self::leaf_range(code)].sort_by(|&a, &b| key(b).total_cmp(&key(a)));
        }
    }
}

/// Emits the wide node for binary node `at` (its children opened, largest area first, until
/// 8) and returns its index.
fn collapse(bin: &[Binary], at: u32, out: &mut Vec<RayBvhNode>) -> u32 {
    let mut kids: Vec<u32> = if bin[at as usize].leaf {
        vec![at]
    } else {
        vec![bin[at as usize].a, bin[at as usize].b]
    };
    while kids.len() < 8 {
        let open = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| !bin[k as usize].leaf)
            .max_by(|(_, &x), (_, &y)| {
                bin[x as usize]
                    .bounds
                    .surface_area()
                    .total_cmp(&bin[y as usize].bounds.surface_area())
            })
            .map(|(i, _)| i);
        let Some(i) = open else { break };
        let k = kids[i] as usize;
        kids[i] = bin[k].a;
        kids.insert(i + 1, bin[k].b);
    }
    let index = out.len() as u32;
    out.push(RayBvhNode {
        lo: [[f32::INFINITY; 8]; 3],
        hi: [[f32::NEG_INFINITY; 8]; 3],
        child: [0; 8],
        valid: 0,
    });
    for (lane, &k) in kids.iter().enumerate() {
        let b = &bin[k as usize];
        let code = if b.leaf {
            LEAF | (b.a << 4) | (b.b - 1)
        } else {
            collapse(bin, k, out)
        };
        let node = &mut out[index as usize];
        for a in 0..3 {
            node.lo[a][lane] = b.bounds.min[a];
            node.hi[a][lane] = b.bounds.max[a];
        }
        node.child[lane] = code;
        node.valid |= 1 << lane;
    }
    index
}

/// `f32::min` with the instruction's rule made explicit: `b` ignored when NaN, else
/// `a < b ? a : b` (what the AVX2 path computes with a select around `vminps`).
#[inline(always)]
fn mn(a: f32, b: f32) -> f32 {
    if b.is_nan() || a < b {
        a
    } else {
        b
    }
}

/// [`mn`]'s counterpart.
#[inline(always)]
fn mx(a: f32, b: f32) -> f32 {
    if b.is_nan() || a > b {
        a
    } else {
        b
    }
}

/// The children of `node` the ray enters no later than `t_limit` (bit `i` = child `i`), with
/// each child's entry: [`FatRay::enter`]'s rule per child, one lane at a time.
#[inline(always)]
pub(crate) fn children_scalar(ray: &FatRay, node: &RayBvhNode, t_limit: f32) -> (u32, [f32; 8]) {
    let o = ray.origin;
    let inv = ray.inv_direction;
    let thin = ray.spread == 0.0 && ray.margin == 0.0;
    let mut hits = 0;
    let mut near = [0f32; 8];
    for (i, near_i) in near.iter_mut().enumerate() {
        if node.valid & (1 << i) == 0 {
            continue;
        }
        let lo = [node.lo[0][i], node.lo[1][i], node.lo[2][i]];
        let hi = [node.hi[0][i], node.hi[1][i], node.hi[2][i]];
        let grow = if thin {
            0.0
        } else {
            let c = |a: usize| ((lo[a] + hi[a]) * 0.5 - o[a]).abs();
            let h = |a: usize| (hi[a] - lo[a]) * 0.5;
            let far_t = ((c(0) + c(1)) + c(2) + ((h(0) + h(1)) + h(2))) * ray.inv_length;
            ray.spread * far_t + ray.margin
        };
        let t0 = |a: usize| ((lo[a] - grow) - o[a]) * inv[a];
        let t1 = |a: usize| ((hi[a] + grow) - o[a]) * inv[a];
        let e = |a: usize| mn(t0(a), t1(a));
        let x = |a: usize| mx(t0(a), t1(a));
        let n = mx(mx(mx(e(0), e(1)), e(2)), 0.0);
        let f = mn(mn(x(0), x(1)), x(2));
        *near_i = n;
        hits |= ((n <= f && n <= t_limit) as u32) << i;
    }
    (hits, near)
}

/// The ray's constants in AVX2 lanes, made once per traversal.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct RayLanes {
    o: [F32x8; 3],
    inv: [F32x8; 3],
    spread: F32x8,
    margin: F32x8,
    inv_length: F32x8,
}

#[cfg(target_arch = "x86_64")]
impl RayLanes {
    #[inline(always)]
    fn new(avx2: Avx2, ray: &FatRay) -> Self {
        Self {
            o: ray.origin.to_array().map(|v| F32x8::splat(avx2, v)),
            inv: ray.inv_direction.to_array().map(|v| F32x8::splat(avx2, v)),
            spread: F32x8::splat(avx2, ray.spread),
            margin: F32x8::splat(avx2, ray.margin),
            inv_length: F32x8::splat(avx2, ray.inv_length),
        }
    }
}

/// [`children_scalar`] in AVX2 lanes: the same operations on the same values, so the same bits.
/// `THIN`: the ray has no cone (no growth: `lo - 0 = lo` exactly); `NAN`: a direction
/// component is zero, so `0 · ∞` may make NaNs, which the minima and maxima skip as
/// [`children_scalar`]'s do (without such a component no lane of a child that exists is NaN,
/// and the plain instructions are the same operations).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn children_avx2<const THIN: bool, const NAN: bool>(
    avx2: Avx2,
    r: &RayLanes,
    node: &RayBvhNode,
    t_limit: f32,
) -> (u32, [f32; 8]) {
    let mn = |a: F32x8, b: F32x8| {
        if NAN {
            F32x8::select(b.is_nan(), a, a.min(b))
        } else {
            a.min(b)
        }
    };
    let mx = |a: F32x8, b: F32x8| {
        if NAN {
            F32x8::select(b.is_nan(), a, a.max(b))
        } else {
            a.max(b)
        }
    };
    let load = |v: &[f32; 8]| F32x8::from_array(avx2, *v);
    let (lx, ly, lz) = (load(&node.lo[0]), load(&node.lo[1]), load(&node.lo[2]));
    let (hx, hy, hz) = (load(&node.hi[0]), load(&node.hi[1]), load(&node.hi[2]));
    let [ox, oy, oz] = r.o;
    let [ix, iy, iz] = r.inv;
    let (t0, t1) = if THIN {
        (
            [(lx - ox) * ix, (ly - oy) * iy, (lz - oz) * iz],
            [(hx - ox) * ix, (hy - oy) * iy, (hz - oz) * iz],
        )
    } else {
        let half = F32x8::splat(avx2, 0.5);
        let c = |l: F32x8, h: F32x8, o: F32x8| ((l + h) * half - o).abs();
        let h = |l: F32x8, h: F32x8| (h - l) * half;
        let far_t =
            ((c(lx, hx, ox) + c(ly, hy, oy)) + c(lz, hz, oz) + ((h(lx, hx) + h(ly, hy)) + h(lz, hz))) * r.inv_length;
        let g = r.spread * far_t + r.margin;
        (
            [((lx - g) - ox) * ix, ((ly - g) - oy) * iy, ((lz - g) - oz) * iz],
            [((hx + g) - ox) * ix, ((hy + g) - oy) * iy, ((hz + g) - oz) * iz],
        )
    };
    let n = mx(
        mx(mx(mn(t0[0], t1[0]), mn(t0[1], t1[1])), mn(t0[2], t1[2])),
        F32x8::zero(avx2),
    );
    let f = mn(mn(mx(t0[0], t1[0]), mx(t0[1], t1[1])), mx(t0[2], t1[2]));
    let enter: M32x8 = n.le(f).and(n.le(F32x8::splat(avx2, t_limit)));
    (enter.bits() & node.valid, n.to_array())
}

/// Visits the leaves of `bvh` that `ray` enters before `*t_limit`, nearest entry first among
/// siblings. `leaf(code, t_enter, box, parent, t_limit)` sees each leaf whose grown box the cone
/// enters before the bound at the time it comes up (`code` for [`RayBvh::leaf_range`], `parent`
/// the index of the node holding it) and may lower `*t_limit`. Every leaf entered before the final bound is visited (module doc).
pub fn traverse_bvh(
    bvh: &RayBvh,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, &Aabb, u32, &mut f32),
) {
    traverse_bvh_from(bvh, 0, ray, t_limit, counters, leaf);
}

/// [`traverse_bvh`] below node `start` only (the root: all of it): the leaves of that subtree
/// the cone enters before the bound.
pub fn traverse_bvh_from(
    bvh: &RayBvh,
    start: u32,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, &Aabb, u32, &mut f32),
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Isa::detected().avx2() {
        // SAFETY: the token proves AVX2, the kernel's one feature.
        unsafe { traverse_bvh_avx2(avx2, bvh, start, ray, t_limit, counters, leaf) };
        return;
    }
    traverse_bvh_body::<false, true>(None, bvh, start, ray, t_limit, counters, leaf);
}

/// [`traverse_bvh`] on the scalar path whatever the machine: the reference the AVX2 path is
/// held to (same leaves, same order, same bounds).
pub fn traverse_bvh_scalar(
    bvh: &RayBvh,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, &Aabb, u32, &mut f32),
) {
    traverse_bvh_body::<false, true>(None, bvh, 0, ray, t_limit, counters, leaf);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn traverse_bvh_avx2(
    avx2: Avx2,
    bvh: &RayBvh,
    start: u32,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, &Aabb, u32, &mut f32),
) {
    let thin = ray.spread == 0.0 && ray.margin == 0.0;
    let nan = !ray.inv_direction.is_finite();
    // Instantiated per kind of ray, so that each skips what it does not need (no closure
    // between: a closure would not be compiled for AVX2, and its lanes' operations would be
    // calls).
    match (thin, nan) {
        (true, false) => traverse_bvh_body::<true, false>(Some(avx2), bvh, start, ray, t_limit, counters, leaf),
        (false, false) => traverse_bvh_body::<false, false>(Some(avx2), bvh, start, ray, t_limit, counters, leaf),
        (true, true) => traverse_bvh_body::<true, true>(Some(avx2), bvh, start, ray, t_limit, counters, leaf),
        (false, true) => traverse_bvh_body::<false, true>(Some(avx2), bvh, start, ray, t_limit, counters, leaf),
    }
}

/// Asks for every cache line of `node` (a hint: changes no result).
#[inline(always)]
fn prefetch_node(node: &RayBvhNode) {
    let p = (node as *const RayBvhNode).cast::<u8>();
    for offset in (0..std::mem::size_of::<RayBvhNode>()).step_by(64) {
        occult_core::simd::prefetch(p.wrapping_add(offset));
    }
}

/// Asks for child `i` of `node`: its triangles if a leaf, else its node (a hint).
#[inline(always)]
pub(crate) fn prefetch_child(bvh: &RayBvh, node: &RayBvhNode, i: usize) {
    if RayBvh::is_leaf(node.child[i]) {
        prefetch_triangles(bvh.leaf_triangles(node.child[i]));
    } else {
        prefetch_node(&bvh.nodes()[node.child[i] as usize]);
    }
}

/// A traversal stack entry whose last field is the entry parameter that orders siblings.
pub(crate) trait StackEntry: Copy {
    /// The entry parameter.
    fn entry(&self) -> f32;
}

impl StackEntry for (u32, f32) {
    #[inline(always)]
    fn entry(&self) -> f32 {
        self.1
    }
}

impl StackEntry for (u32, u64, f32) {
    #[inline(always)]
    fn entry(&self) -> f32 {
        self.2
    }
}

/// Pushes `item` onto `stack[..*top]`, the siblings pushed since `base` kept farthest first so
/// that the nearest pops first (insertion by entry; equal entries keep their push order).
#[inline(always)]
pub(crate) fn push_by_entry<T: StackEntry>(
    stack: &mut [std::mem::MaybeUninit<T>],
    base: usize,
    top: &mut usize,
    item: T,
) {
    let mut j = *top;
    // SAFETY: slots `base..top` were written.
    while j > base && unsafe { stack[j - 1].assume_init() }.entry() < item.entry() {
        let moved = unsafe { stack[j - 1].assume_init() };
        stack[j].write(moved);
        j -= 1;
    }
    stack[j].write(item);
    *top += 1;
}

/// The body of [`traverse_bvh`], on AVX2 lanes when `avx2` is given (`THIN`, `NAN`: see
/// [`children_avx2`]), else on [`children_scalar`].
#[inline(always)]
fn traverse_bvh_body<const THIN: bool, const NAN: bool>(
    avx2: Option<Avx2>,
    bvh: &RayBvh,
    start: u32,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    mut leaf: impl FnMut(u32, f32, &Aabb, u32, &mut f32),
) {
    // A match, not `Option::map`: a closure would not be compiled for AVX2 (see
    // `traverse_bvh_avx2`).
    #[cfg(target_arch = "x86_64")]
    #[allow(clippy::manual_map)]
    let lanes = match avx2 {
        Some(a) => Some((a, RayLanes::new(a, ray))),
        None => None,
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2;
    let nodes = bvh.nodes();
    if nodes.is_empty() || (start == 0 && ray.enter(&bvh.bounds).is_none_or(|(e, _)| e > *t_limit)) {
        return;
    }
    // Entries `(parent node · 8 + lane, entry)`: a leaf's box is read from its parent's lanes.
    let mut stack = [const { std::mem::MaybeUninit::<(u32, f32)>::uninit() }; STACK];
    let mut top = 0usize;
    let mut current = Some(start);
    loop {
        if let Some(index) = current.take() {
            counters.nodes_visited += 1;
            let node = &nodes[index as usize];
            let (hits, near) = match &lanes {
                #[cfg(target_arch = "x86_64")]
                Some((a, r)) => children_avx2::<THIN, NAN>(*a, r, node, *t_limit),
                _ => children_scalar(ray, node, *t_limit),
            };
            // Farthest first onto the stack, so the nearest pops first (insertion by entry;
            // equal entries keep lane order, the same on both paths).
            let base = top;
            let mut rest = hits;
            while rest != 0 {
                let i = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                prefetch_child(bvh, node, i);
                push_by_entry(&mut stack, base, &mut top, (index * 8 + i as u32, near[i]));
            }
        }
        if top == 0 {
            return;
        }
        top -= 1;
        // SAFETY: slots below `top` were written (pushes write before raising `top`).
        let (slot, t_enter) = unsafe { stack[top].assume_init() };
        if t_enter > *t_limit {
            continue;
        }
        let parent = &nodes[(slot / 8) as usize];
        let lane = (slot % 8) as usize;
        let code = parent.child[lane];
        if RayBvh::is_leaf(code) {
            counters.nodes_visited += 1;
            counters.leaves_visited += 1;
            leaf(code, t_enter, &parent.child_bounds(lane), slot / 8, t_limit);
        } else {
            current = Some(code);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raycast::tests::{awkward_ray, soup, xorshift};
    use occult_core::{intersect_ray_triangle, Ray};

    fn build(p: &[Vec3], t: &[[u32; 3]], leaf: usize) -> RayBvh {
        RayBvh::build_triangles(p, t, RayBvhConfig { max_leaf_size: leaf }).expect("a soup builds")
    }

    /// Every triangle in exactly one leaf, within the leaf's box; leaves within size.
    #[test]
    fn leaves_partition_the_triangles() {
        let (p, t) = soup(1000, 3);
        // Over the parallel build's threshold too.
        let (big_p, big_t) = soup(3 * PARALLEL, 4);
        for (p, t, leaf) in [(&p, &t, 1), (&p, &t, 4), (&p, &t, 8), (&big_p, &big_t, 4)] {
            let bvh = build(p, t, leaf);
            let mut seen = vec![0u32; t.len()];
            for (code, b) in bvh.leaves() {
                let r = RayBvh::leaf_range(code);
                assert!(r.len() <= leaf);
                for &i in &bvh.triangles()[r] {
                    seen[i as usize] += 1;
                    for v in t[i as usize] {
                        assert!(b.contains_point(p[v as usize]));
                    }
                }
            }
            assert!(seen.iter().all(|&s| s == 1));
        }
        // Coincident triangles (no separating bin) still make leaves within size.
        let same: Vec<[u32; 3]> = vec![[0, 1, 2]; 100];
        let bvh = build(&p, &same, 4);
        assert_eq!(
            bvh.leaves().map(|(c, _)| RayBvh::leaf_range(c).len()).sum::<usize>(),
            100
        );
        assert!(bvh.leaves().all(|(c, _)| RayBvh::leaf_range(c).len() <= 4));
        assert!(build(&p, &[], 4).nodes().is_empty());
        assert!(RayBvh::build_triangles(&p, &t, RayBvhConfig { max_leaf_size: 9 }).is_err());
    }

    /// The nearest hit through the traversal (bound lowered at each hit) is the linear scan's.
    #[test]
    fn nearest_hit_matches_linear_scan() {
        let (p, t) = soup(500, 7);
        let bvh = build(&p, &t, 4);
        let mut rnd = xorshift(99);
        for _ in 0..1000 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 30.0 - 10.0;
            let dir = Vec3::new(rnd(), rnd(), rnd()) * 10.0 - origin * 0.2;
            let ray = Ray::new(origin, dir);
            let tri = |i: u32| t[i as usize].map(|v| p[v as usize]);
            let brute = (0..t.len() as u32)
                .filter_map(|i| {
                    let [a, b, c] = tri(i);
                    intersect_ray_triangle(&ray, a, b, c).map(|h| h.t)
                })
                .fold(f32::INFINITY, f32::min);
            let mut limit = f32::INFINITY;
            let fat = FatRay::new(origin, dir, 0.0, 0.0);
            traverse_bvh(
                &bvh,
                &fat,
                &mut limit,
                &mut TraversalCounters::default(),
                |code, _, _, _, limit| {
                    for &i in &bvh.triangles()[RayBvh::leaf_range(code)] {
                        let [a, b, c] = tri(i);
                        if let Some(h) = intersect_ray_triangle(&ray, a, b, c) {
                            *limit = limit.min(h.t);
                        }
                    }
                },
            );
            assert_eq!(limit, brute);
        }
    }

    /// A cone visits every leaf whose box it enters before the bound ([`FatRay::enter`] on
    /// the leaf's box, by linear scan), and only those.
    #[test]
    fn cone_visits_every_leaf_it_touches() {
        let (p, t) = soup(400, 5);
        let bvh = build(&p, &t, 2);
        for k in 0..60 {
            let origin = Vec3::new(-5.0, k as f32 * 0.2, 2.0);
            let ray = FatRay::new(origin, Vec3::new(1.0, 0.05, 0.1), 0.01, 0.001);
            let bound = 12.0;
            let mut limit = bound;
            let mut visited = vec![];
            traverse_bvh(
                &bvh,
                &ray,
                &mut limit,
                &mut TraversalCounters::default(),
                |c, _, _, _, _| visited.push(c),
            );
            visited.sort_unstable();
            let mut expect: Vec<u32> = bvh
                .leaves()
                .filter(|(_, b)| ray.enter(b).is_some_and(|(e, _)| e <= bound))
                .map(|(c, _)| c)
                .collect();
            expect.sort_unstable();
            assert_eq!(visited, expect, "ray {k}");
        }
    }

    /// The dispatched traversal (AVX2 where present) visits the same leaves in the same order
    /// with the same entries and bounds as the scalar one.
    #[test]
    fn dispatched_traversal_matches_the_scalar_one() {
        if !Isa::detected().has_avx2() {
            eprintln!("note: no AVX2 here; the dispatched path is the scalar one, compared with itself");
        }
        let (p, t) = soup(800, 13);
        let flat: Vec<Vec3> = p.iter().map(|v| Vec3::new(v.x, 2.0, v.z)).collect();
        let mut rnd = xorshift(5);
        let mut leaves = 0;
        for pos in [&p, &flat] {
            let bvh = build(pos, &t, 4);
            for k in 0..400 {
                // On a slab plane of the root's box, along it, now and then.
                let ray = awkward_ray(&mut rnd, k, bvh.bounds().min.y);
                let run = |scalar: bool| {
                    let mut seen = vec![];
                    let mut limit = 40.0f32;
                    let mut c = TraversalCounters::default();
                    let f = |l: u32, e: f32, b: &Aabb, p: u32, lim: &mut f32| {
                        seen.push((l, e.to_bits(), b.min.x.to_bits(), p));
                        if seen.len() % 3 == 0 {
                            *lim = lim.min(e + 1.0);
                        }
                    };
                    if scalar {
                        traverse_bvh_scalar(&bvh, &ray, &mut limit, &mut c, f);
                    } else {
                        traverse_bvh(&bvh, &ray, &mut limit, &mut c, f);
                    }
                    (seen, limit.to_bits(), c)
                };
                let (a, b) = (run(true), run(false));
                leaves += a.0.len();
                assert_eq!(a, b, "ray {k}");
            }
        }
        assert!(leaves > 500, "{leaves}");
    }
}
