//! Packets of thin rays from one origin through a [`RayBvh`] ([`traverse_bvh_packet`]): the
//! primary rays of up to [`PACKET`] neighbouring pixels walk the tree together, so that a node
//! is fetched, and the stack worked, once for all of them.
//!
//! # References
//! - Wald, Slusallek, Benthin & Wagner, "Interactive Rendering with Coherent Ray Tracing",
//!   Eurographics 2001: coherent rays traced together share each node's memory access.
//! - Wald, Boulos & Shirley, "Ray Tracing Deformable Scenes Using Dynamic Bounding Volume
//!   Hierarchies", ACM TOG 26(1), 2007: BVH packet traversal with a set of active rays per
//!   node, the packet descending while any of its rays enters.
//!
//! Each ray still decides for itself: at a node, every ray of the packet that reached it is
//! tested against the 8 children with exactly the single-ray test of [`crate::traverse_bvh`]
//! for a thin ray (the same operations on the same values, so the same bits), and a child goes
//! onto the stack with the set of rays that enter it no later than their own bounds. Children
//! are taken nearest first by the least entry among their rays. A leaf is handed over with its
//! rays, each of which entered its box before its bound when the leaf was pushed and has a bound
//! no nearer than the packet's entry when it comes up. So every leaf a ray of the packet enters
//! before its final bound is handed over with that ray (each box holds its children's, and a
//! bound only falls), as the single-ray traversal hands it over; the order differs.
//!
//! The rays share their origin, so a node's corners relative to it are computed once per node
//! (the first subtraction of the slab test), and a leaf's triangles relative to it once per
//! leaf ([`crate::raycast::intersect8_packet`]).

use crate::bvh8::{children_scalar, prefetch_child, push_by_entry, RayBvhNode, STACK};
use crate::raycast::TraversalCounters;
use crate::{FatRay, RayBvh};
use occult_core::simd::{Avx2, Isa};
#[cfg(target_arch = "x86_64")]
use occult_core::simd::{F32x8, I32x8};
use occult_core::Vec3;

/// Most rays in a [`RayPacket`]: one bit each of a `u64`.
pub const PACKET: usize = 64;

/// Up to [`PACKET`] thin rays from one origin (see the module doc).
#[derive(Clone, Debug)]
pub struct RayPacket {
    origin: Vec3,
    /// Per axis, the rays' inverse direction components (structure of arrays).
    inv: [[f32; PACKET]; 3],
    len: usize,
    kind: Kind,
    /// Cones around the rays ([`RayPacket::fat`]): `(spread, margin, the rays' largest
    /// inverse direction length)`; `None`: thin rays.
    cone: Option<(f32, f32, f32)>,
}

/// What the slab test of a packet may skip.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// Every inverse component finite and nonzero, each axis of one sign for all rays: a slab's
    /// entry is the plane on the side the rays come from, no minimum or maximum needed (the
    /// same values: a product by a positive number keeps order, by a negative one reverses it).
    /// The bits of the signs of x, y, z.
    Uniform(u8),
    /// Every inverse component finite, signs mixed.
    Mixed,
    /// A direction component is zero (`0 · ∞` may make NaNs in the slab test).
    Nan,
}

impl RayPacket {
    /// The rays `origin + t · directions[r]`.
    ///
    /// # Panics
    /// With more than [`PACKET`] directions.
    #[inline]
    pub fn new(origin: Vec3, directions: &[Vec3]) -> Self {
        assert!(
            directions.len() <= PACKET,
            "a packet holds at most {PACKET} rays, not {}",
            directions.len()
        );
        let mut inv = [[0f32; PACKET]; 3];
        let (mut finite, mut nonzero) = (true, true);
        let (mut negative, mut positive) = (0u8, 0u8);
        for (r, d) in directions.iter().enumerate() {
            let v = d.recip();
            for a in 0..3 {
                inv[a][r] = v[a];
                finite &= v[a].is_finite();
                nonzero &= v[a] != 0.0;
                negative |= u8::from(v[a] < 0.0) << a;
                positive |= u8::from(v[a] > 0.0) << a;
            }
        }
        let kind = match (finite, nonzero && negative & positive == 0) {
            (false, _) => Kind::Nan,
            (true, true) => Kind::Uniform(negative),
            (true, false) => Kind::Mixed,
        };
        Self {
            origin,
            inv,
            len: directions.len(),
            kind,
            cone: None,
        }
    }

    /// The rays `origin + t · directions[r]`, each widened to the cone of radius
    /// `spread · t + margin` (a [`FatRay`]): a child box is entered when the box grown by the
    /// cone's radius at its far side is, as [`FatRay::enter`] grows it, measured with the
    /// rays' shortest direction (the largest radius any of them has there), so every box a
    /// ray's cone enters is entered by that ray of the packet.
    ///
    /// # Panics
    /// With more than [`PACKET`] directions.
    #[inline]
    pub fn fat(origin: Vec3, directions: &[Vec3], spread: f32, margin: f32) -> Self {
        let mut packet = Self::new(origin, directions);
        let inv_length = directions.iter().map(|d| 1.0 / d.length()).fold(0.0f32, f32::max);
        packet.cone = Some((spread, margin, inv_length));
        packet
    }

    /// The common origin.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// How many rays it holds.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when it holds no ray.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Ray `r` as the thin ray of the single-ray test (its direction is not kept: the test
    /// reads only the origin and the inverse direction).
    #[inline(always)]
    fn thin_ray(&self, r: usize) -> FatRay {
        FatRay {
            origin: self.origin,
            direction: Vec3::ZERO,
            inv_direction: Vec3::new(self.inv[0][r], self.inv[1][r], self.inv[2][r]),
            inv_length: 0.0,
            spread: 0.0,
            margin: 0.0,
        }
    }
}

/// Visits the leaves of `bvh` that the rays of `packet` named by `active` (bit `r`: ray `r`)
/// enter no later than their bounds `t_limit[r]`. `leaf(code, rays, t_limit)` sees each such
/// leaf once, with the set of rays that entered its box (see the module doc), and may lower
/// any ray's bound. Every leaf a ray enters before its final bound is handed over with it.
/// Counts one node visit per node or leaf the packet takes from the stack.
pub fn traverse_bvh_packet(
    bvh: &RayBvh,
    packet: &RayPacket,
    active: u64,
    t_limit: &mut [f32; PACKET],
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, u64, &mut [f32; PACKET]),
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Isa::detected().avx2() {
        // SAFETY: the token proves AVX2, the kernel's one feature.
        unsafe { traverse_packet_avx2(avx2, bvh, packet, active, t_limit, counters, leaf) };
        return;
    }
    packet_body::<0>(None, bvh, packet, active, t_limit, counters, leaf);
}

/// [`traverse_bvh_packet`] on the scalar path whatever the machine: the reference the AVX2
/// path is held to (same leaves, rays, order and bounds).
pub fn traverse_bvh_packet_scalar(
    bvh: &RayBvh,
    packet: &RayPacket,
    active: u64,
    t_limit: &mut [f32; PACKET],
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, u64, &mut [f32; PACKET]),
) {
    packet_body::<0>(None, bvh, packet, active, t_limit, counters, leaf);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn traverse_packet_avx2(
    avx2: Avx2,
    bvh: &RayBvh,
    packet: &RayPacket,
    active: u64,
    t_limit: &mut [f32; PACKET],
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, u64, &mut [f32; PACKET]),
) {
    // Instantiated per kind of packet (no closure between: see `traverse_bvh`'s AVX2 path).
    match packet.kind {
        Kind::Nan => packet_body::<NAN>(Some(avx2), bvh, packet, active, t_limit, counters, leaf),
        Kind::Mixed => packet_body::<MIXED>(Some(avx2), bvh, packet, active, t_limit, counters, leaf),
        Kind::Uniform(_) => packet_body::<UNIFORM>(Some(avx2), bvh, packet, active, t_limit, counters, leaf),
    }
}

/// Instantiations of [`packet_body`] by [`Kind`].
const NAN: u8 = 0;
const MIXED: u8 = 1;
const UNIFORM: u8 = 2;

/// The rays of `packet` in `m` whose bound is no nearer than `t`.
#[inline(always)]
fn still_within(m: u64, t: f32, t_limit: &[f32; PACKET]) -> u64 {
    let mut keep = 0;
    let mut rest = m;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        keep |= ((t <= t_limit[r]) as u64) << r;
    }
    keep
}

/// For node `node` and the rays `m`: per child, the rays that enter it no later than their
/// bounds (`masks`) and the least of their entries (`near`, `+∞` where none), one ray at a time
/// through the single-ray child test.
#[inline(always)]
fn children_of_rays_scalar(
    packet: &RayPacket,
    node: &RayBvhNode,
    m: u64,
    t_limit: &[f32; PACKET],
) -> ([u64; 8], [f32; 8]) {
    let mut masks = [0u64; 8];
    let mut near = [f32::INFINITY; 8];
    let mut rest = m;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        let (hits, n) = children_scalar(&packet.thin_ray(r), node, t_limit[r]);
        let mut h = hits;
        while h != 0 {
            let c = h.trailing_zeros() as usize;
            h &= h - 1;
            masks[c] |= 1 << r;
            // An entered child's entry is a number (`n <= f` held).
            near[c] = if n[c] < near[c] { n[c] } else { near[c] };
        }
    }
    (masks, near)
}

/// [`children_of_rays_scalar`] in AVX2 lanes: the node's corners less the origin once, then
/// per ray the thin single-ray test, the rays' sets gathered in two words of lanes. `KIND`:
/// with [`NAN`] the minima and maxima skip NaNs as the scalar test's do; with [`UNIFORM`] each
/// slab's entry and exit planes are picked once for the packet (the same values the minima and
/// maxima give, see [`Kind::Uniform`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn children_of_rays_avx2<const KIND: u8>(
    avx2: Avx2,
    packet: &RayPacket,
    node: &RayBvhNode,
    m: u64,
    t_limit: &[f32; PACKET],
) -> ([u64; 8], [f32; 8]) {
    let mn = |a: F32x8, b: F32x8| {
        if KIND == NAN {
            F32x8::select(b.is_nan(), a, a.min(b))
        } else {
            a.min(b)
        }
    };
    let mx = |a: F32x8, b: F32x8| {
        if KIND == NAN {
            F32x8::select(b.is_nan(), a, a.max(b))
        } else {
            a.max(b)
        }
    };
    let o = packet.origin;
    let load = |v: &[f32; 8], o: f32| F32x8::from_array(avx2, *v) - F32x8::splat(avx2, o);
    let mut lo = [load(&node.lo[0], o.x), load(&node.lo[1], o.y), load(&node.lo[2], o.z)];
    let mut hi = [load(&node.hi[0], o.x), load(&node.hi[1], o.y), load(&node.hi[2], o.z)];
    if KIND == UNIFORM {
        // `lo` becomes the entry planes, `hi` the exit planes.
        let Kind::Uniform(negative) = packet.kind else {
            unreachable!("the uniform kernel runs on uniform packets only");
        };
        for a in 0..3 {
            if negative & (1 << a) != 0 {
                std::mem::swap(&mut lo[a], &mut hi[a]);
            }
        }
    }
    let zero = F32x8::zero(avx2);
    let inf = F32x8::splat(avx2, f32::INFINITY);
    let valid = occult_core::simd::M32x8::from_bits(avx2, node.valid);
    let mut near = inf;
    let mut words = [I32x8::zero(avx2); 2];
    for (w, word) in words.iter_mut().enumerate() {
        let mut rest = (m >> (32 * w)) as u32;
        while rest != 0 {
            let bit = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            let r = 32 * w + bit;
            // No `array::map` here: its closure is not always inlined, and then it is not
            // compiled for AVX2 (every lane operation a call).
            let inv = [
                F32x8::splat(avx2, packet.inv[0][r]),
                F32x8::splat(avx2, packet.inv[1][r]),
                F32x8::splat(avx2, packet.inv[2][r]),
            ];
            let t0 = [lo[0] * inv[0], lo[1] * inv[1], lo[2] * inv[2]];
            let t1 = [hi[0] * inv[0], hi[1] * inv[1], hi[2] * inv[2]];
            let (n, f) = if KIND == UNIFORM {
                (t0[0].max(t0[1]).max(t0[2]).max(zero), t1[0].min(t1[1]).min(t1[2]))
            } else {
                (
                    mx(mx(mx(mn(t0[0], t1[0]), mn(t0[1], t1[1])), mn(t0[2], t1[2])), zero),
                    mn(mn(mx(t0[0], t1[0]), mx(t0[1], t1[1])), mx(t0[2], t1[2])),
                )
            };
            let enter = n.le(f).and(n.le(F32x8::splat(avx2, t_limit[r]))).and(valid);
            near = near.min(F32x8::select(enter, n, inf));
            *word = word.or(enter.to_i32x8().and(I32x8::splat(avx2, (1u32 << bit) as i32)));
        }
    }
    let (low, high) = (words[0].to_array(), words[1].to_array());
    let masks = std::array::from_fn(|c| low[c] as u32 as u64 | (high[c] as u32 as u64) << 32);
    (masks, near.to_array())
}

/// `node` with every child's box grown by the cone's radius at the box's far side (the
/// arithmetic of [`crate::bvh8`]'s fat child test, operation for operation), for a packet's
/// cones `(spread, margin, inv_length)` from `o`.
#[inline(always)]
fn grow(node: &RayBvhNode, o: Vec3, (spread, margin, inv_length): (f32, f32, f32)) -> RayBvhNode {
    let mut grown = *node;
    for i in 0..8 {
        let lo = [node.lo[0][i], node.lo[1][i], node.lo[2][i]];
        let hi = [node.hi[0][i], node.hi[1][i], node.hi[2][i]];
        let c = |a: usize| ((lo[a] + hi[a]) * 0.5 - o[a]).abs();
        let h = |a: usize| (hi[a] - lo[a]) * 0.5;
        let far_t = ((c(0) + c(1)) + c(2) + ((h(0) + h(1)) + h(2))) * inv_length;
        let g = spread * far_t + margin;
        for a in 0..3 {
            grown.lo[a][i] = lo[a] - g;
            grown.hi[a][i] = hi[a] + g;
        }
    }
    grown
}

/// The body of [`traverse_bvh_packet`], on AVX2 lanes when `avx2` is given.
#[inline(always)]
fn packet_body<const KIND: u8>(
    avx2: Option<Avx2>,
    bvh: &RayBvh,
    packet: &RayPacket,
    active: u64,
    t_limit: &mut [f32; PACKET],
    counters: &mut TraversalCounters,
    mut leaf: impl FnMut(u32, u64, &mut [f32; PACKET]),
) {
    #[cfg(not(target_arch = "x86_64"))]
    let _ = avx2;
    let nodes = bvh.nodes();
    if nodes.is_empty() {
        return;
    }
    let live = if packet.len == PACKET {
        u64::MAX
    } else {
        (1u64 << packet.len) - 1
    };
    // The root's box is not tested: its children are, ray by ray.
    let root = active & live;
    if root == 0 {
        return;
    }
    // Entries `(parent node · 8 + lane, rays, least entry)`.
    let mut stack = [const { std::mem::MaybeUninit::<(u32, u64, f32)>::uninit() }; STACK];
    let mut top = 0usize;
    let mut current = Some((0u32, root));
    loop {
        if let Some((index, m)) = current.take() {
            counters.nodes_visited += 1;
            let node = &nodes[index as usize];
            let grown;
            let tested = match packet.cone {
                Some(cone) => {
                    grown = grow(node, packet.origin, cone);
                    &grown
                }
                None => node,
            };
            let (masks, near) = match avx2 {
                #[cfg(target_arch = "x86_64")]
                Some(a) => children_of_rays_avx2::<KIND>(a, packet, tested, m, t_limit),
                _ => children_of_rays_scalar(packet, tested, m, t_limit),
            };
            // Farthest first onto the stack, so the nearest pops first (insertion by entry;
            // equal entries keep lane order, the same on both paths).
            let base = top;
            for (i, &rays) in masks.iter().enumerate() {
                if rays == 0 {
                    continue;
                }
                prefetch_child(bvh, node, i);
                push_by_entry(&mut stack, base, &mut top, (index * 8 + i as u32, rays, near[i]));
            }
        }
        if top == 0 {
            return;
        }
        top -= 1;
        // SAFETY: slots below `top` were written (pushes write before raising `top`).
        let (slot, rays, t_enter) = unsafe { stack[top].assume_init() };
        let rays = still_within(rays, t_enter, t_limit);
        if rays == 0 {
            continue;
        }
        let code = nodes[(slot / 8) as usize].child[(slot % 8) as usize];
        if RayBvh::is_leaf(code) {
            counters.nodes_visited += 1;
            counters.leaves_visited += 1;
            leaf(code, rays, t_limit);
        } else {
            current = Some((code, rays));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raycast::intersect8_packet;
    use crate::raycast::tests::{soup, xorshift};
    use crate::{traverse_bvh, RayBvhConfig, ShearedRay};
    use occult_core::Aabb;

    fn build(p: &[Vec3], t: &[[u32; 3]], leaf: usize) -> RayBvh {
        RayBvh::build_triangles(p, t, RayBvhConfig { max_leaf_size: leaf }).expect("a soup builds")
    }

    /// Directions of an 8×8 tile of "pixels" around `centre`, `step` apart; with `axis_aligned`
    /// some of them have zero components.
    fn tile(centre: Vec3, step: f32, axis_aligned: bool) -> Vec<Vec3> {
        (0..PACKET)
            .map(|k| {
                let (i, j) = ((k % 8) as f32 - 3.5, (k / 8) as f32 - 3.5);
                let d = centre + Vec3::new(i * step, j * step, 0.0);
                if axis_aligned && k % 5 == 0 {
                    Vec3::new(0.0, d.y, d.z)
                } else {
                    d
                }
            })
            .collect()
    }

    /// Every ray's nearest hit through the packet (each ray's bound lowered at its hits) is its
    /// nearest hit over all the triangles (to within rounding, rarely), and every leaf a ray enters
    /// before its final bound reaches it; the scalar path sees the same leaves, rays and bounds.
    #[test]
    fn packet_finds_each_rays_nearest_hit() {
        let (p, t) = soup(600, 11);
        let flat: Vec<Vec3> = p.iter().map(|v| Vec3::new(v.x, 2.0, v.z)).collect();
        let mut rnd = xorshift(17);
        let (mut hit_rays, mut rounded) = (0, 0);
        let mut kinds = [0u32; 3];
        for (pos, leaf_size) in [(&p, 4), (&flat, 4), (&p, 1), (&flat, 8)] {
            let bvh = build(pos, &t, leaf_size);
            let tris: Vec<crate::LeafTriangle> = bvh
                .triangles()
                .iter()
                .map(|&i| {
                    let c = t[i as usize].map(|v| pos[v as usize]);
                    crate::LeafTriangle {
                        corners: c,
                        normal: (c[1] - c[0]).cross(c[2] - c[0]),
                    }
                })
                .collect();
            for k in 0..60 {
                let mut origin = Vec3::new(rnd(), rnd(), rnd()) * 30.0 - 10.0;
                if k % 5 == 3 {
                    // On a slab plane of the root's box: with a zero direction component,
                    // `0 · ∞` in the slab test.
                    origin.y = bvh.bounds().min.y;
                }
                let centre = Vec3::new(rnd(), rnd(), rnd()) * 10.0 - origin * 0.2;
                let dirs = tile(centre, [0.002, 0.05, 0.5][k % 3], k % 4 == 1 || k % 5 == 3);
                let n = PACKET - (k % 7);
                let packet = RayPacket::new(origin, &dirs[..n]);
                kinds[match packet.kind {
                    Kind::Nan => 0,
                    Kind::Mixed => 1,
                    Kind::Uniform(_) => 2,
                }] += 1;
                let sheared: Vec<ShearedRay> = dirs.iter().map(|&d| ShearedRay::new(origin, d)).collect();
                let run = |scalar: bool| {
                    let mut limit = [40.0f32; PACKET];
                    let mut seen = vec![];
                    let mut c = TraversalCounters::default();
                    let f = |code: u32, rays: u64, limit: &mut [f32; PACKET]| {
                        seen.push((code, rays));
                        let range = RayBvh::leaf_range(code);
                        let mut found = [f32::INFINITY; PACKET];
                        intersect8_packet(&tris[range], origin, &sheared, rays, 0.0, limit, |r, hits, ts| {
                            for (i, &t) in ts.iter().enumerate() {
                                if hits & (1 << i) != 0 {
                                    found[r] = found[r].min(t);
                                }
                            }
                        });
                        for r in 0..PACKET {
                            limit[r] = limit[r].min(found[r]);
                        }
                    };
                    if scalar {
                        traverse_bvh_packet_scalar(&bvh, &packet, u64::MAX, &mut limit, &mut c, f);
                    } else {
                        traverse_bvh_packet(&bvh, &packet, u64::MAX, &mut limit, &mut c, f);
                    }
                    (seen, limit.map(f32::to_bits), c)
                };
                let (a, b) = (run(true), run(false));
                assert_eq!(a, b, "packet {k}: scalar and dispatched paths");
                let (seen, limits, _) = a;
                for r in 0..n {
                    let ray = FatRay::new(origin, dirs[r], 0.0, 0.0);
                    // The nearest hit over every leaf.
                    let limit = bvh
                        .leaves()
                        .map(|(code, _)| {
                            let (hits, ts) = sheared[r].intersect8(&tris[RayBvh::leaf_range(code)], 0xff, 0.0, 40.0);
                            (0..8)
                                .filter(|i| hits & (1 << i) != 0)
                                .map(|i| ts[i])
                                .fold(40.0f32, f32::min)
                        })
                        .fold(40.0f32, f32::min);
                    // A hit may round a few units in the last place nearer than its leaf's box
                    // entry, so a traversal, with one ray or a packet, may skip the leaf of a hit
                    // that ties the nearest to within rounding; nothing farther.
                    let got = f32::from_bits(limits[r]);
                    assert!(
                        (got - limit).abs() <= 4.0 * f32::EPSILON * limit,
                        "packet {k}, ray {r}: {got} against {limit}"
                    );
                    rounded += (got != limit) as u32;
                    hit_rays += (limit < 40.0) as u32;
                    // Every leaf the ray enters before its final bound came with it.
                    let final_bound = f32::from_bits(limits[r]);
                    let entered: Vec<u32> = bvh
                        .leaves()
                        .filter(|(_, b): &(u32, Aabb)| ray.enter(b).is_some_and(|(e, _)| e < final_bound))
                        .map(|(c, _)| c)
                        .collect();
                    for code in entered {
                        assert!(
                            seen.iter().any(|&(c, rays)| c == code && rays & (1 << r) != 0),
                            "packet {k}, ray {r}: leaf {code} missed"
                        );
                    }
                }
                assert_eq!(limits[n..].iter().filter(|&&l| l != 40f32.to_bits()).count(), 0);
            }
        }
        assert!(hit_rays > 800, "{hit_rays}");
        assert!(kinds.iter().all(|&k| k >= 10), "packets of each kind: {kinds:?}");
        assert!(
            rounded * 200 < hit_rays,
            "{rounded} of {hit_rays} rays differ in rounding"
        );
    }

    /// A packet of cones hands each ray every leaf whose box that ray's own cone enters
    /// before its bound (the bounds held fixed), on both paths alike.
    #[test]
    fn fat_packet_enters_every_box_its_cones_enter() {
        let (p, t) = soup(600, 5);
        let bvh = build(&p, &t, 4);
        let mut rnd = xorshift(23);
        let mut checked = 0;
        for k in 0..60 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 30.0 - 10.0;
            let centre = Vec3::new(rnd(), rnd(), rnd()) * 10.0 - origin * 0.2;
            let dirs = tile(centre, [0.002, 0.05, 0.5][k % 3], k % 4 == 1);
            let (spread, margin) = ([0.0, 1e-3, 2e-2][k % 3], [0.0, 1e-4, 0.05][(k / 3) % 3]);
            let packet = RayPacket::fat(origin, &dirs, spread, margin);
            let run = |scalar: bool| {
                let mut limit = [25.0f32; PACKET];
                let mut seen = vec![];
                let mut c = TraversalCounters::default();
                let f = |code: u32, rays: u64, _: &mut [f32; PACKET]| seen.push((code, rays));
                if scalar {
                    traverse_bvh_packet_scalar(&bvh, &packet, u64::MAX, &mut limit, &mut c, f);
                } else {
                    traverse_bvh_packet(&bvh, &packet, u64::MAX, &mut limit, &mut c, f);
                }
                seen
            };
            let seen = run(true);
            assert_eq!(seen, run(false), "packet {k}: scalar and dispatched paths");
            for (r, &d) in dirs.iter().enumerate() {
                let ray = FatRay::new(origin, d, spread, margin);
                let mut bound = 25.0f32;
                let mut c = TraversalCounters::default();
                traverse_bvh(&bvh, &ray, &mut bound, &mut c, |code, _, _, _, _| {
                    checked += 1;
                    assert!(
                        seen.iter().any(|&(s, rays)| s == code && rays & (1 << r) != 0),
                        "packet {k}, ray {r}: leaf {code} missed"
                    );
                });
            }
        }
        assert!(checked > 1_000, "{checked}");
    }

    #[test]
    #[should_panic(expected = "at most 64 rays")]
    fn packet_of_too_many_rays() {
        let _ = RayPacket::new(Vec3::ZERO, &[Vec3::X; PACKET + 1]);
    }
}
