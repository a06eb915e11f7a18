//! Front-to-back ray traversal of a [`RayOctree`], for rays with a thickness.
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

use crate::octree::{ray::lower_max, RayOctree, MAX_OCTREE_DEPTH};
use occult_core::simd::{Avx2, Isa};
#[cfg(target_arch = "x86_64")]
use occult_core::simd::{F32x4, F32x8, I32x8, M32x4, M32x8};
use occult_core::{sheared_edge_functions, Aabb, Vec3};

/// A ray with a thickness growing linearly with `t` (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FatRay {
    /// Origin.
    pub origin: Vec3,
    /// Direction (any length; `t` is in its units).
    pub direction: Vec3,
    pub(crate) inv_direction: Vec3,
    pub(crate) inv_length: f32,
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

/// A ray prepared for the watertight ray–triangle test (Woop, Benthin & Wald, "Watertight
/// Ray/Triangle Intersection", JCGT 2(1), 2013, §2–3): the axis permutation and shear that
/// depend on the ray only, computed once per ray instead of once per triangle. The arithmetic
/// is [`occult_core::intersect_ray_triangle`]'s, operation for operation (the edge functions
/// are the same function, [`occult_core::sheared_edge_functions`]), so the results are the
/// same bits (tested).
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    /// The origin's coordinates in the permuted order `kx, ky, kz`.
    origin: [f32; 3],
    k: [usize; 3],
    s: [f32; 3],
}

impl ShearedRay {
    /// The shear of the ray `origin + t · direction`.
    #[inline]
    pub fn new(origin: Vec3, direction: Vec3) -> Self {
        let d = direction;
        let kz = d.abs().max_position();
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Self {
            origin: [origin[kx], origin[ky], origin[kz]],
            k: [kx, ky, kz],
            s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
        }
    }

    /// True when the ray starts at `origin`.
    pub fn is_from(&self, origin: Vec3) -> bool {
        self.origin == self.k.map(|k| origin[k])
    }

    /// The hit parameter `t` of triangle `p` when the ray hits it with `t` in
    /// `[t_min, t_max]` (both faces; shared edges hit by at least one of their triangles).
    #[inline]
    pub fn intersect(&self, p: &[Vec3; 3], t_min: f32, t_max: f32) -> Option<f32> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        let [ox, oy, oz] = self.origin;
        // Each corner relative to the origin, in the permuted axes: read from memory at the
        // ray's axis indices (the same subtractions as `p - origin`, then picked).
        let rel = |v: &Vec3| {
            let v: &[f32; 3] = v.as_ref();
            (v[kx] - ox, v[ky] - oy, v[kz] - oz)
        };
        let (a, b, c) = (rel(&p[0]), rel(&p[1]), rel(&p[2]));
        let ax = a.0 - sx * a.2;
        let ay = a.1 - sy * a.2;
        let bx = b.0 - sx * b.2;
        let by = b.1 - sy * b.2;
        let cx = c.0 - sx * c.2;
        let cy = c.1 - sy * c.2;
        let (u, v, w, det) = sheared_edge_functions([ax, ay], [bx, by], [cx, cy])?;
        let t_scaled = u * (sz * a.2) + v * (sz * b.2) + w * (sz * c.2);
        let t = t_scaled * (1.0 / det);
        (t >= t_min && t <= t_max).then_some(t)
    }
}

/// A triangle as a ray caster stores it in leaf order: its corners and its normal scaled by its
/// area (the layout [`ShearedRay::intersect8`] reads).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct LeafTriangle {
    /// Corners.
    pub corners: [Vec3; 3],
    /// Normal scaled by the area.
    pub normal: Vec3,
}

// `intersect8` gathers corner `c`, axis `a` of triangle `i` at float `12 i + 3 c + a`.
const _: () = assert!(std::mem::size_of::<LeafTriangle>() == 48 && std::mem::size_of::<Vec3>() == 12);

/// Asks the memory system for every cache line of `tris` at once, so that the lines a leaf's
/// later groups of eight need are on their way while the first group is tested (the hardware
/// would otherwise take one miss after another). A hint: it changes no result.
#[inline]
pub fn prefetch_triangles(tris: &[LeafTriangle]) {
    let start = tris.as_ptr().cast::<u8>();
    for offset in (0..std::mem::size_of_val(tris)).step_by(64) {
        occult_core::simd::prefetch(start.wrapping_add(offset));
    }
}

impl ShearedRay {
    /// [`ShearedRay::intersect`] on up to 8 triangles at once: bit `i` of the result is set
    /// when `tris[i]` (tested only where bit `i` of `active` is set) is hit with `t` in
    /// `[t_min, t_max]`, and lane `i` of the array holds that `t`. The same bits as the
    /// one-triangle test (AVX2 lanes where present: the same operations in the same order).
    pub fn intersect8(&self, tris: &[LeafTriangle], active: u32, t_min: f32, t_max: f32) -> (u32, [f32; 8]) {
        let active = active & (((1u64 << tris.len().min(8)) - 1) as u32);
        if active == 0 {
            return (0, [0.0; 8]);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Isa::detected().avx2() {
            // SAFETY: the token proves AVX2, the kernel's one feature.
            return unsafe { self.intersect8_avx2(avx2, tris, active, t_min, t_max) };
        }
        self.intersect8_scalar(tris, active, t_min, t_max)
    }

    /// [`ShearedRay::intersect8`] one triangle at a time.
    pub fn intersect8_scalar(&self, tris: &[LeafTriangle], active: u32, t_min: f32, t_max: f32) -> (u32, [f32; 8]) {
        let mut hits = 0;
        let mut t = [0f32; 8];
        for (i, tri) in tris.iter().enumerate().take(8) {
            if active & (1 << i) != 0 {
                if let Some(h) = self.intersect(&tri.corners, t_min, t_max) {
                    hits |= 1 << i;
                    t[i] = h;
                }
            }
        }
        (hits, t)
    }

    /// [`ShearedRay::intersect8`] in AVX2 lanes, for an `active` already limited to lanes
    /// below `tris.len()`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn intersect8_avx2(
        &self,
        avx2: Avx2,
        tris: &[LeafTriangle],
        active: u32,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; 8]) {
        debug_assert!(active >> tris.len().min(8) == 0);
        let [kx, ky, kz] = self.k;
        let o = self.origin.map(|v| F32x8::splat(avx2, v));
        // Coordinate `axis` of corner `corner` of every active triangle, minus the origin's.
        // SAFETY: only `active` lanes are read, all below `tris.len()` (the caller's promise).
        let rel = |corner: usize, axis: usize, o: F32x8| unsafe { gather_corner(avx2, tris, active, corner, axis) } - o;
        let corners = [
            [rel(0, kx, o[0]), rel(0, ky, o[1]), rel(0, kz, o[2])],
            [rel(1, kx, o[0]), rel(1, ky, o[1]), rel(1, kz, o[2])],
            [rel(2, kx, o[0]), rel(2, ky, o[1]), rel(2, kz, o[2])],
        ];
        self.finish8(avx2, corners, tris, active, t_min, t_max)
    }

    /// The rest of [`ShearedRay::intersect8_avx2`] from the corners relative to the origin, in
    /// the ray's permuted axes (`corners[c][j]`: corner `c`, axis `k[j]`).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn finish8(
        &self,
        avx2: Avx2,
        corners: [[F32x8; 3]; 3],
        tris: &[LeafTriangle],
        active: u32,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; 8]) {
        let [sx, sy, sz] = self.s.map(|v| F32x8::splat(avx2, v));
        let [[a0, a1, a2], [b0, b1, b2], [c0, c1, c2]] = corners;
        let shear = |p: F32x8, q: F32x8, s: F32x8| p - s * q;
        let (ax, ay) = (shear(a0, a2, sx), shear(a1, a2, sy));
        let (bx, by) = (shear(b0, b2, sx), shear(b1, b2, sy));
        let (cx, cy) = (shear(c0, c2, sx), shear(c1, c2, sy));
        let cross = |p: F32x8, q: F32x8, r: F32x8, s: F32x8| p * q - r * s;
        let u = cross(cx, by, cy, bx);
        let v = cross(ax, cy, ay, cx);
        let w = cross(bx, ay, by, ax);
        let zero = F32x8::zero(avx2);
        let any = |f: &dyn Fn(F32x8) -> M32x8| f(u).or(f(v)).or(f(w));
        // Lanes where an edge function rounded to zero take the scalar test's f64 path.
        let exact = any(&|e| e.eq(zero)).bits() & active;
        let miss = any(&|e| e.lt(zero)).and(any(&|e| e.gt(zero)));
        let det = u + v + w;
        let t_scaled = u * (sz * a2) + v * (sz * b2) + w * (sz * c2);
        let t = t_scaled * (F32x8::splat(avx2, 1.0) / det);
        let ok = t
            .ge(F32x8::splat(avx2, t_min))
            .and_not(miss.or(det.eq(zero)))
            .and(t.le(F32x8::splat(avx2, t_max)));
        let mut hits = ok.bits() & active & !exact;
        let mut out = t.to_array();
        let mut rest = exact;
        while rest != 0 {
            let i = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if let Some(h) = self.intersect(&tris[i].corners, t_min, t_max) {
                hits |= 1 << i;
                out[i] = h;
            }
        }
        (hits, out)
    }
}

/// What [`ShearedRay::candidates8`] finds among up to 8 triangles (bit `i`: triangle `i`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidates8 {
    /// The thin ray's hits with `t` in `[t_min, t_max]`, as [`ShearedRay::intersect8`] gives
    /// them (the same bits).
    pub hits: u32,
    /// The hits' parameters (lane `i` where bit `i` of `hits` is set).
    pub t: [f32; 8],
    /// The triangles that may come within the cone around the ray (a superset of those that
    /// do; see [`ShearedRay::candidates8`]).
    pub close: u32,
    /// Per close triangle, a parameter no greater than that of any of its points within the
    /// cone: the triangle reaches the ray's path before a bound `b` only if this is `<= b`.
    pub t_reach: [f32; 8],
}

impl ShearedRay {
    /// The thin hits of [`ShearedRay::intersect8`] and, in the same pass over the corners, the
    /// triangles that the cone of radius `spread · t + margin` around the ray may touch at a
    /// parameter `t <= t_max`.
    ///
    /// Why it is conservative:
    /// - A point at distance `r` across the ray, at parameter `t`, has the parameter `t ± r/|d_kz|`
    ///   along the ray's major axis (`kz`), and every point of a triangle has at most its corners'
    ///   greatest. So a point of the triangle within the cone lies at `t <= t_far`, where
    ///   `t_far = (t_corner_max + margin/|d_kz|) / (1 − spread/|d_kz|)` (at most `t_max`, and
    ///   `t_max` where `spread/|d_kz|` reaches a half); the
    ///   radius there, `R = spread · t_far + margin`, bounds the cone wherever the triangle is in it.
    /// - The shear projects along the ray onto the plane across its major axis, which moves a point
    ///   at distance `R` from the ray to at most `R · |d| / |d_kz|` from it (`sec`). A triangle
    ///   with a point that close to the ray has each sheared edge function, signed by the
    ///   triangle's winding, at least `−R · sec · |edge|` at the ray (the function grows by `|edge|`
    ///   per unit of distance), and `|edge|` is at most the sum of the edge's two component
    ///   lengths. Each edge function is allowed besides four units of rounding of its two
    ///   products. Both windings are tried (all three at least `−allowance`, or all at most
    ///   `+allowance`), so a winding too thin to sign reliably is close either way, and so is
    ///   a NaN.
    /// - Such a point's parameter is at least the corners' least along `kz`, less `R/|d_kz|`:
    ///   `t_reach`.
    #[allow(clippy::too_many_arguments)]
    pub fn candidates8(
        &self,
        tris: &[LeafTriangle],
        active: u32,
        spread: f32,
        margin: f32,
        t_min: f32,
        t_max: f32,
    ) -> Candidates8 {
        let active = active & (((1u64 << tris.len().min(8)) - 1) as u32);
        if active == 0 {
            return Candidates8 {
                hits: 0,
                t: [0.0; 8],
                close: 0,
                t_reach: [0.0; 8],
            };
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Isa::detected().avx2() {
            // SAFETY: the token proves AVX2, the kernel's one feature.
            return unsafe { self.candidates8_avx2(avx2, tris, active, spread, margin, t_min, t_max) };
        }
        self.candidates8_scalar(tris, active, spread, margin, t_min, t_max)
    }

    /// The constants of [`ShearedRay::candidates8`]'s cone: `(|1/d_kz|, 1 − spread/|d_kz|`
    /// (`None` from a half down: a cone too wide to bound by the corners, taken at `t_max`),
    /// `sec · (1 + 2⁻¹⁰))`.
    #[inline(always)]
    fn cone_constants(&self, spread: f32) -> (f32, Option<f32>, f32) {
        let [sx, sy, sz] = self.s;
        let inv_kz = sz.abs();
        let lean = 1.0 - spread * inv_kz;
        (
            inv_kz,
            (lean > 0.5).then_some(lean),
            (1.0 + sx * sx + sy * sy).sqrt() * (1.0 + 1.0 / 1024.0),
        )
    }

    /// [`ShearedRay::candidates8`] one triangle at a time (the same operations as the AVX2
    /// lanes, so the same bits).
    #[allow(clippy::too_many_arguments)]
    pub fn candidates8_scalar(
        &self,
        tris: &[LeafTriangle],
        active: u32,
        spread: f32,
        margin: f32,
        t_min: f32,
        t_max: f32,
    ) -> Candidates8 {
        let (hits, t) = self.intersect8_scalar(tris, active, t_min, t_max);
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        let [ox, oy, oz] = self.origin;
        let (inv_kz, lean, sec) = self.cone_constants(spread);
        // The rules of the AVX2 minimum and maximum, so that the two paths give the same bits.
        let min = |x: f32, y: f32| if x < y { x } else { y };
        let max = |x: f32, y: f32| if x > y { x } else { y };
        let mut close = 0;
        let mut t_reach = [0f32; 8];
        for (i, tri) in tris.iter().enumerate().take(8) {
            if active & (1 << i) == 0 {
                continue;
            }
            let rel = |v: &Vec3| {
                let v: &[f32; 3] = v.as_ref();
                (v[kx] - ox, v[ky] - oy, v[kz] - oz)
            };
            let p = &tri.corners;
            let (a, b, c) = (rel(&p[0]), rel(&p[1]), rel(&p[2]));
            let (ta, tb, tc) = (sz * a.2, sz * b.2, sz * c.2);
            let t_far = match lean {
                Some(lean) => (max(max(ta, tb), tc) + margin * inv_kz) / lean,
                None => t_max,
            };
            let radius = spread * max(min(t_far, t_max), 0.0) + margin;
            let r = radius * sec;
            let (ax, ay) = (a.0 - sx * a.2, a.1 - sy * a.2);
            let (bx, by) = (b.0 - sx * b.2, b.1 - sy * b.2);
            let (cx, cy) = (c.0 - sx * c.2, c.1 - sy * c.2);
            let edge = |px: f32, py: f32, qx: f32, qy: f32| {
                let (m, n) = (qx * py, qy * px);
                (
                    m - n,
                    r * ((px - qx).abs() + (py - qy).abs()) + ROUNDING * (m.abs() + n.abs()),
                )
            };
            let (u, lu) = edge(bx, by, cx, cy);
            let (v, lv) = edge(cx, cy, ax, ay);
            let (w, lw) = edge(ax, ay, bx, by);
            // Either winding, whatever the sign `u + v + w` rounds to.
            let positive = u >= 0.0 - lu && v >= 0.0 - lv && w >= 0.0 - lw;
            let negative = u <= lu && v <= lv && w <= lw;
            // NaN edge functions compare false: close too.
            let nan = u.is_nan() || v.is_nan() || w.is_nan();
            if positive || negative || nan {
                close |= 1 << i;
                t_reach[i] = min(min(ta, tb), tc) - radius * inv_kz;
            }
        }
        Candidates8 {
            hits,
            t,
            close,
            t_reach,
        }
    }

    /// [`ShearedRay::candidates8`] in AVX2 lanes, for an `active` already limited to lanes
    /// below `tris.len()`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    fn candidates8_avx2(
        &self,
        avx2: Avx2,
        tris: &[LeafTriangle],
        active: u32,
        spread: f32,
        margin: f32,
        t_min: f32,
        t_max: f32,
    ) -> Candidates8 {
        let [kx, ky, kz] = self.k;
        let o = self.origin.map(|v| F32x8::splat(avx2, v));
        // SAFETY: only `active` lanes are read, all below `tris.len()` (the caller's promise).
        let rel = |corner: usize, axis: usize, o: F32x8| unsafe { gather_corner(avx2, tris, active, corner, axis) } - o;
        let corners = [
            [rel(0, kx, o[0]), rel(0, ky, o[1]), rel(0, kz, o[2])],
            [rel(1, kx, o[0]), rel(1, ky, o[1]), rel(1, kz, o[2])],
            [rel(2, kx, o[0]), rel(2, ky, o[1]), rel(2, kz, o[2])],
        ];
        let (hits, t) = self.finish8(avx2, corners, tris, active, t_min, t_max);
        let (inv_kz, lean, sec) = self.cone_constants(spread);
        let splat = |v: f32| F32x8::splat(avx2, v);
        let [sx, sy, sz] = self.s.map(splat);
        let [[a0, a1, a2], [b0, b1, b2], [c0, c1, c2]] = corners;
        let (ta, tb, tc) = (sz * a2, sz * b2, sz * c2);
        let t_far = match lean {
            Some(lean) => (ta.max(tb).max(tc) + splat(margin) * splat(inv_kz)) / splat(lean),
            None => splat(t_max),
        };
        let zero = F32x8::zero(avx2);
        let radius = splat(spread) * t_far.min(splat(t_max)).max(zero) + splat(margin);
        let r = radius * splat(sec);
        let shear = |p: F32x8, q: F32x8, s: F32x8| p - s * q;
        let (ax, ay) = (shear(a0, a2, sx), shear(a1, a2, sy));
        let (bx, by) = (shear(b0, b2, sx), shear(b1, b2, sy));
        let (cx, cy) = (shear(c0, c2, sx), shear(c1, c2, sy));
        let rounding = splat(ROUNDING);
        let edge = |px: F32x8, py: F32x8, qx: F32x8, qy: F32x8| {
            let (m, n) = (qx * py, qy * px);
            (
                m - n,
                r * ((px - qx).abs() + (py - qy).abs()) + rounding * (m.abs() + n.abs()),
            )
        };
        let (u, lu) = edge(bx, by, cx, cy);
        let (v, lv) = edge(cx, cy, ax, ay);
        let (w, lw) = edge(ax, ay, bx, by);
        // Either winding, whatever the sign `u + v + w` rounds to; NaN edge functions close.
        let positive = u.ge(zero - lu).and(v.ge(zero - lv)).and(w.ge(zero - lw));
        let negative = u.le(lu).and(v.le(lv)).and(w.le(lw));
        let nan = u.is_nan().or(v.is_nan()).or(w.is_nan());
        let close = positive.or(negative).or(nan).bits() & active;
        let t_reach = ta.min(tb).min(tc) - radius * splat(inv_kz);
        Candidates8 {
            hits,
            t,
            close,
            t_reach: t_reach.keep(M32x8::from_bits(avx2, close)).to_array(),
        }
    }
}

/// Units of rounding allowed on each product of a sheared edge function in
/// [`ShearedRay::candidates8`] (four units of the last place of `f32`).
const ROUNDING: f32 = 4.0 * f32::EPSILON;

/// Axis `axis` of corner `corner` of the `active` triangles of `tris`, in lanes.
///
/// # Safety
/// Every bit of `active` names a triangle of `tris`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn gather_corner(avx2: Avx2, tris: &[LeafTriangle], active: u32, corner: usize, axis: usize) -> F32x8 {
    const STRIDE: i32 = (std::mem::size_of::<LeafTriangle>() / 4) as i32;
    let lanes = I32x8::lane_index(avx2).wrapping_mul(I32x8::splat(avx2, STRIDE));
    // SAFETY: lane `i` (read only where `active` is set) reads float `12 i + 3 corner + axis`
    // of triangle `i`, which the caller vouches exists.
    unsafe {
        F32x8::gather_masked(
            avx2,
            tris.as_ptr().cast::<f32>().wrapping_add(3 * corner + axis),
            lanes,
            M32x8::from_bits(avx2, active),
        )
    }
}

/// The eight-triangle test of [`ShearedRay::intersect8`] for each ray `r` of `rays` named by
/// bit `r` of `mask`, all of them from `origin` (`rays[r]` made by `ShearedRay::new(origin,
/// ·)`), against the same up to 8 triangles with `t` in `[t_min, t_max[r]]`: `hit(r, hits,
/// t)` for each ray that hits any, with the bits and parameters `intersect8` gives. The
/// triangles are read once for all the rays (AVX2 lanes where present, their corners relative
/// to the common origin computed once: the same subtractions each ray's own test makes).
pub fn intersect8_packet(
    tris: &[LeafTriangle],
    origin: Vec3,
    rays: &[ShearedRay],
    mask: u64,
    t_min: f32,
    t_max: &[f32],
    hit: impl FnMut(usize, u32, &[f32; 8]),
) {
    debug_assert!(tris.len() <= 8, "a leaf of {} triangles", tris.len());
    debug_assert!(
        (0..rays.len()).all(|r| mask & (1 << r) == 0 || rays[r].is_from(origin)),
        "every ray of the packet starts at its origin"
    );
    let active = ((1u64 << tris.len().min(8)) - 1) as u32;
    if active == 0 || mask == 0 {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Isa::detected().avx2() {
        // SAFETY: the token proves AVX2, the kernel's one feature.
        unsafe { intersect8_packet_avx2(avx2, tris, origin, rays, mask, t_min, t_max, hit) };
        return;
    }
    intersect8_packet_scalar(tris, rays, mask, t_min, t_max, hit);
}

/// [`intersect8_packet`] one ray at a time through [`ShearedRay::intersect8_scalar`].
pub fn intersect8_packet_scalar(
    tris: &[LeafTriangle],
    rays: &[ShearedRay],
    mask: u64,
    t_min: f32,
    t_max: &[f32],
    mut hit: impl FnMut(usize, u32, &[f32; 8]),
) {
    let active = ((1u64 << tris.len().min(8)) - 1) as u32;
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        let (hits, t) = rays[r].intersect8_scalar(tris, active, t_min, t_max[r]);
        if hits != 0 {
            hit(r, hits, &t);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
fn intersect8_packet_avx2(
    avx2: Avx2,
    tris: &[LeafTriangle],
    origin: Vec3,
    rays: &[ShearedRay],
    mask: u64,
    t_min: f32,
    t_max: &[f32],
    mut hit: impl FnMut(usize, u32, &[f32; 8]),
) {
    let active = ((1u64 << tris.len().min(8)) - 1) as u32;
    // Every corner relative to the common origin, once: `rel[c][a]`, unpermuted axes.
    let o = origin.to_array().map(|v| F32x8::splat(avx2, v));
    // SAFETY: `active` names exactly the triangles of `tris` (at most 8).
    let g = |c: usize, a: usize| unsafe { gather_corner(avx2, tris, active, c, a) } - o[a];
    // Written out, not through `array::map`, whose closure is not always inlined.
    let rel = [
        [g(0, 0), g(0, 1), g(0, 2)],
        [g(1, 0), g(1, 1), g(1, 2)],
        [g(2, 0), g(2, 1), g(2, 2)],
    ];
    let mut rest = mask;
    while rest != 0 {
        let r = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        let ray = &rays[r];
        let [kx, ky, kz] = ray.k;
        let corners = [
            [rel[0][kx], rel[0][ky], rel[0][kz]],
            [rel[1][kx], rel[1][ky], rel[1][kz]],
            [rel[2][kx], rel[2][ky], rel[2][kz]],
        ];
        let (hits, t) = ray.finish8(avx2, corners, tris, active, t_min, t_max[r]);
        if hits != 0 {
            hit(r, hits, &t);
        }
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

/// The two halves of internal node box `b` along each axis, as `(lower, upper)` pairs of
/// `(min, max)` corners: `[lo0, hi0, lo1, hi1]`. A flat axis (bit `8 + a` of `split_info`) is not
/// split: its lower half spans the whole axis. These are exactly the children's stored boxes
/// (the build's split, [`lower_max`]).
#[inline]
fn halves(b: &Aabb, split_info: u16) -> [Vec3; 4] {
    [b.min, lower_max(b, split_info >> 8), b.center(), b.max]
}

impl FatRay {
    /// The cone's radius bound over box `b` (see [`FatRay::enter`]).
    #[inline]
    fn grow(&self, b: &Aabb) -> f32 {
        if self.spread == 0.0 && self.margin == 0.0 {
            return 0.0;
        }
        let far_t = ((b.center() - self.origin).abs().element_sum() + b.half_extent().element_sum()) * self.inv_length;
        self.spread * far_t + self.margin
    }

    /// Entry and exit parameters (entry clamped at 0) of the 8 children of internal node box
    /// `b` grown by `grow` (the radius bound over `b`, which bounds each child's own), child
    /// `i` at index `i`: the parametric form of the slab test (Revelles et al. 2000), 12 plane
    /// distances for all 8 children instead of 48. An empty interval (entry > exit) is a miss.
    #[inline]
    fn enter_children(&self, b: &Aabb, split_info: u16, grow: f32) -> [(f32, f32); 8] {
        let [lo0, hi0, lo1, hi1] = halves(b, split_info);
        let g = Vec3::splat(grow);
        let t = |p: Vec3| (p - self.origin) * self.inv_direction;
        let (a0, b0) = (t(lo0 - g), t(hi0 + g));
        let (a1, b1) = (t(lo1 - g), t(hi1 + g));
        // Per half and axis: entry and exit (f32::min/max ignore the NaN of 0 · ∞, as in
        // `enter`).
        let e = [a0.min(b0), a1.min(b1)];
        let x = [a0.max(b0), a1.max(b1)];
        let mut out = [(0f32, 0f32); 8];
        for (i, o) in out.iter_mut().enumerate() {
            let (hx, hy, hz) = (i & 1, (i >> 1) & 1, (i >> 2) & 1);
            let near = e[hx].x.max(e[hy].y).max(e[hz].z).max(0.0);
            let far = x[hx].x.min(x[hy].y).min(x[hz].z);
            *o = (near, far);
        }
        out
    }
}

/// Visits the leaves of `octree` that `ray` enters before `*t_limit`, front to back.
/// `leaf(node_index, t_enter, t_exit, t_limit)` sees each non-empty leaf once and may lower
/// `*t_limit`; leaves whose entry lies beyond the bound at the time they come up are skipped.
///
/// Traversal (the parametric octree traversal of Revelles, Ureña & Lastra 2000, made fat): an
/// internal node's 8 children are tested together from 12 plane distances (the node's
/// halves, grown by the cone's radius bound over the node), and pushed in the order the ray's
/// direction signs give (child `i ^ mask`, `mask` = the axes the ray runs down): front to back
/// for a thin ray, and nearly so for a cone. A leaf is then tested against its own grown box,
/// so the leaves visited are exactly those whose grown box the cone enters before the bound
/// (on a tree whose leaves were tightened, [`RayOctree::tighten_leaves`], those whose own box the
/// cone enters inside their parent's grown octant: the part of a tight box outside its octant
/// belongs to neighbouring leaves).
pub fn traverse(
    octree: &RayOctree,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, f32, &mut f32),
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Isa::detected().avx2() {
        // SAFETY: the token proves AVX2, the kernel's one feature.
        unsafe { traverse_avx2(avx2, octree, ray, t_limit, counters, leaf) };
        return;
    }
    traverse_body(None, octree, ray, t_limit, counters, leaf);
}

/// [`traverse`] on the scalar path whatever the machine: the reference the AVX2 path is held
/// to (same leaves, same order, same bounds).
pub fn traverse_scalar(
    octree: &RayOctree,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, f32, &mut f32),
) {
    traverse_body(None, octree, ray, t_limit, counters, leaf);
}

/// [`traverse`] compiled for AVX2, the children tested in its lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn traverse_avx2(
    avx2: Avx2,
    octree: &RayOctree,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    leaf: impl FnMut(u32, f32, f32, &mut f32),
) {
    traverse_body(Some(avx2), octree, ray, t_limit, counters, leaf);
}

/// The children of internal node box `b` the ray enters no later than `t_limit`: a bit mask
/// (child `i` at bit `i`, only occupied children) and each child's entry parameter.
#[inline(always)]
fn children_scalar(ray: &FatRay, b: &Aabb, split_info: u16, grow: f32, t_limit: f32) -> (u32, [f32; 8]) {
    let kids = ray.enter_children(b, split_info, grow);
    let mut hits = 0;
    let mut near = [0f32; 8];
    for (i, &(e, x)) in kids.iter().enumerate() {
        near[i] = e;
        hits |= ((split_info & (1 << i) != 0 && e <= x && e <= t_limit) as u32) << i;
    }
    (hits, near)
}

/// [`children_scalar`] with the 8 children in the lanes of AVX2 registers: the same
/// operations on the same values, so the same bits. The two halves' corners sit in the two
/// halves of one [`F32x8`] (lane 3 of each unused); [`F32x8::min`]/[`F32x8::max`] are glam's
/// `Vec3::min`/`max` lane for lane (`a < b ? a : b`), and f32::min/max's "a NaN operand yields
/// the other" is reproduced by selects.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn children_avx2(avx2: Avx2, ray: &FatRay, b: &Aabb, split_info: u16, grow: f32, t_limit: f32) -> (u32, [f32; 8]) {
    let lo = F32x4::from_array(avx2, [b.min.x, b.min.y, b.min.z, 0.0]);
    let hi = F32x4::from_array(avx2, [b.max.x, b.max.y, b.max.z, 0.0]);
    // `halves`: the centre (Aabb::center's arithmetic), the lower halves' max corner the
    // box's own max on a flat axis (lane 3, read from bit 11, is 0 either way).
    let mid = (lo + hi) * F32x4::splat(avx2, 0.5);
    let flat = M32x4::from_bits(avx2, (split_info >> 8) as u32);
    let low_max = F32x4::select(flat, hi, mid);
    let g = F32x8::splat(avx2, grow);
    let o = ray.origin;
    let o = F32x8::from_array(avx2, [o.x, o.y, o.z, 0.0, o.x, o.y, o.z, 0.0]);
    let inv = ray.inv_direction;
    let inv = F32x8::from_array(avx2, [inv.x, inv.y, inv.z, 1.0, inv.x, inv.y, inv.z, 1.0]);
    // Lanes 0..4: half 0, 4..8: half 1; `(p ∓ g - o) · inv` as `t(p ∓ g)` computes it.
    let a = (F32x8::from_halves(lo, mid) - g - o) * inv;
    let c = (F32x8::from_halves(low_max, hi) + g - o) * inv;
    let e = a.min(c);
    let x = a.max(c);
    // Lane i is child i: half (i & 1) on x, (i >> 1) & 1 on y, (i >> 2) & 1 on z.
    let px = I32x8::from_array(avx2, [0, 4, 0, 4, 0, 4, 0, 4]);
    let py = I32x8::from_array(avx2, [1, 1, 5, 5, 1, 1, 5, 5]);
    let pz = I32x8::from_array(avx2, [2, 2, 2, 2, 6, 6, 6, 6]);
    // f32::max / f32::min: a NaN operand yields the other one.
    let max = |a: F32x8, b: F32x8| F32x8::select(b.is_nan(), a, a.max(b));
    let min = |a: F32x8, b: F32x8| F32x8::select(b.is_nan(), a, a.min(b));
    let near = max(max(e.permute(px), e.permute(py)), e.permute(pz));
    // max(NaN, 0) = 0 as in f32::max.
    let near = near.max(F32x8::zero(avx2));
    let far = min(min(x.permute(px), x.permute(py)), x.permute(pz));
    let enter = near.le(far).and(near.le(F32x8::splat(avx2, t_limit)));
    let hits = enter.bits() & (split_info as u32 & 0xff);
    (hits, near.to_array())
}

/// The body of [`traverse`], compiled once per instruction set.
#[inline(always)]
fn traverse_body(
    avx2: Option<Avx2>,
    octree: &RayOctree,
    ray: &FatRay,
    t_limit: &mut f32,
    counters: &mut TraversalCounters,
    mut leaf: impl FnMut(u32, f32, f32, &mut f32),
) {
    let nodes = octree.nodes();
    let info = octree.split_info();
    let Some(root) = nodes.first() else { return };
    let Some((t0, _)) = ray.enter(&root.bounds) else {
        return;
    };
    let mask = (ray.direction.x < 0.0) as usize
        | ((ray.direction.y < 0.0) as usize) << 1
        | ((ray.direction.z < 0.0) as usize) << 2;
    const STACK: usize = 8 * MAX_OCTREE_DEPTH as usize + 8;
    // Room for the deepest tree any build accepts (each level pops one node and pushes at most
    // 8). Uninitialized: a traversal runs per ray and per mesh instance met, and clearing the
    // whole stack each time costs more than a shallow traversal.
    let mut stack = [const { std::mem::MaybeUninit::<(u32, f32)>::uninit() }; STACK];
    stack[0].write((0, t0));
    let mut top = 1;
    while top > 0 {
        top -= 1;
        // SAFETY: slots below `top` were written (pushes write before raising `top`).
        let (index, t_enter) = unsafe { stack[top].assume_init() };
        if t_enter > *t_limit {
            continue;
        }
        counters.nodes_visited += 1;
        let node = &nodes[index as usize];
        if node.is_leaf() {
            if node.count > 0 {
                // The leaf's own grown box (its parent's test grew it by the parent's bound).
                let Some((t_enter, t_exit)) = ray.enter(&node.bounds) else {
                    continue;
                };
                if t_enter > *t_limit {
                    continue;
                }
                counters.leaves_visited += 1;
                leaf(index, t_enter, t_exit, t_limit);
            }
            continue;
        }
        let si = info[index as usize];
        let grow = ray.grow(&node.bounds);
        let (hits, near) = match avx2 {
            #[cfg(target_arch = "x86_64")]
            Some(avx2) => children_avx2(avx2, ray, &node.bounds, si, grow, *t_limit),
            _ => children_scalar(ray, &node.bounds, si, grow, *t_limit),
        };
        // Farthest first onto the stack, so the nearest pops first: child `i` is pushed in
        // the order of `j = i ^ mask`, so the hit bits are permuted into that order (each
        // direction bit swaps halves of the mask) and taken from the highest down.
        let mut ordered = hits;
        if mask & 1 != 0 {
            ordered = ((ordered & 0x55) << 1) | ((ordered >> 1) & 0x55);
        }
        if mask & 2 != 0 {
            ordered = ((ordered & 0x33) << 2) | ((ordered >> 2) & 0x33);
        }
        if mask & 4 != 0 {
            ordered = ((ordered & 0x0f) << 4) | ((ordered >> 4) & 0x0f);
        }
        while ordered != 0 {
            let j = 31 - ordered.leading_zeros() as usize;
            ordered &= !(1 << j);
            let i = j ^ mask;
            stack[top].write((node.first + i as u32, near[i]));
            top += 1;
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::octree::RayOctreeConfig;
    use occult_core::{intersect_ray_triangle, Ray};

    /// Uniform numbers in [0, 1) from a xorshift generator.
    pub(crate) fn xorshift(mut s: u64) -> impl FnMut() -> f32 {
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// Ray `k` of a series for comparing traversals: random, thin and fat in turn, some along
    /// axes (zero direction components), some on the slab plane `y = slab_y` and along it.
    pub(crate) fn awkward_ray(rnd: &mut impl FnMut() -> f32, k: usize, slab_y: f32) -> FatRay {
        let mut origin = Vec3::new(rnd(), rnd(), rnd()) * 16.0 - 3.0;
        let mut dir = Vec3::new(rnd(), rnd(), rnd()) * 2.0 - 1.0;
        if k.is_multiple_of(5) {
            dir[k % 3] = 0.0;
        }
        if k.is_multiple_of(7) {
            origin.y = slab_y;
            dir.y = 0.0;
        }
        let (spread, margin) = if k.is_multiple_of(2) { (0.0, 0.0) } else { (0.002, 0.01) };
        FatRay::new(origin, dir, spread, margin)
    }

    /// `n` random triangles of about 1.5 units in a 10-unit cube.
    pub(crate) fn soup(n: usize, seed: u64) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut rnd = xorshift(seed);
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
        let cfg = RayOctreeConfig {
            max_depth: 6,
            max_leaf_size: 8,
        };
        let plain = RayOctree::build_triangles(&p, &t, cfg).expect("a triangle soup builds");
        // And with leaves tightened to their triangles' bounds clipped to the octant, as lzb
        // does: the same nearest hits.
        let mut tight = plain.clone();
        tight.tighten_leaves(|n, list| {
            list.iter()
                .fold(Aabb::EMPTY, |a, &i| {
                    a.union(Aabb::from_points(t[i as usize].map(|v| p[v as usize])))
                })
                .intersection(n.bounds)
        });
        assert_ne!(plain.nodes(), tight.nodes());
        let mut rnd = xorshift(99);
        let mut counters = TraversalCounters::default();
        for k in 0..1000 {
            let o = if k % 2 == 0 { &plain } else { &tight };
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
            traverse(o, &fat, &mut limit, &mut counters, |leaf, _, _, limit| {
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
        let o = RayOctree::build_triangles(
            &p,
            &t,
            RayOctreeConfig {
                max_depth: 5,
                max_leaf_size: 4,
            },
        )
        .expect("a triangle soup builds");
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

    /// The dispatched traversal (AVX2 where present) visits the same leaves in the same order
    /// with the same bounds as the scalar one: thin and fat rays, rays along axes (zero
    /// direction components), origins on slab planes, flat layers, bounds lowered on the way.
    #[test]
    fn dispatched_traversal_matches_the_scalar_one() {
        if !Isa::detected().has_avx2() {
            eprintln!("note: no AVX2 here; the dispatched path is the scalar one, compared with itself");
        }
        let (p, t) = soup(600, 13);
        let flat: Vec<Vec3> = p.iter().map(|v| Vec3::new(v.x, 2.0, v.z)).collect();
        let mut rnd = xorshift(5);
        let mut leaves = 0;
        for pos in [&p, &flat] {
            let o = RayOctree::build_triangles(
                pos,
                &t,
                RayOctreeConfig {
                    max_depth: 7,
                    max_leaf_size: 4,
                },
            )
            .expect("a triangle soup builds");
            for k in 0..400 {
                let ray = awkward_ray(&mut rnd, k, o.bounds().min.y);
                let run = |scalar: bool| {
                    let mut seen = vec![];
                    let mut limit = 40.0f32;
                    let mut c = TraversalCounters::default();
                    let f = |l: u32, e: f32, x: f32, lim: &mut f32| {
                        seen.push((l, e.to_bits(), x.to_bits()));
                        if seen.len() % 3 == 0 {
                            *lim = lim.min(x);
                        }
                    };
                    if scalar {
                        traverse_scalar(&o, &ray, &mut limit, &mut c, f);
                    } else {
                        traverse(&o, &ray, &mut limit, &mut c, f);
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

    /// The sheared ray gives intersect_ray_triangle's bits, hits and misses alike.
    #[test]
    fn sheared_ray_matches_the_watertight_test() {
        let (p, t) = soup(300, 5);
        let mut rnd = xorshift(17);
        let mut hits = 0;
        for k in 0..200 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 20.0 - 5.0;
            // Aimed at a triangle's centroid (axis-aligned now and then).
            let aim = t[k % t.len()].map(|v| p[v as usize]);
            let mut dir = (aim[0] + aim[1] + aim[2]) / 3.0 - origin;
            if k % 7 == 0 {
                dir.x = 0.0;
            }
            let ray = Ray::new(origin, dir);
            let sheared = ShearedRay::new(origin, dir);
            for tri in &t {
                let [a, b, c] = tri.map(|v| p[v as usize]);
                let want = intersect_ray_triangle(&ray, a, b, c).map(|h| h.t.to_bits());
                let got = sheared.intersect(&[a, b, c], 0.0, f32::INFINITY).map(f32::to_bits);
                assert_eq!(got, want);
                hits += want.is_some() as usize;
            }
        }
        assert!(hits > 50);
    }

    /// Eight at a time gives the one-at-a-time bits: random triangles, rays aimed at corners
    /// (edge functions of zero: the f64 path), along axes, partial groups and masks.
    /// The direction from `origin` to triangle `aim`'s centroid, a corner or an edge's midpoint
    /// (by `k`), with one component zeroed when `k` is a multiple of `zero_every`.
    fn aimed(origin: Vec3, aim: [Vec3; 3], k: usize, zero_every: usize) -> Vec3 {
        let mut dir = match k % 3 {
            0 => (aim[0] + aim[1] + aim[2]) / 3.0 - origin,
            1 => aim[k % 3] - origin,
            _ => (aim[0] + aim[1]) * 0.5 - origin,
        };
        if k.is_multiple_of(zero_every) {
            dir[k % 3] = 0.0;
        }
        dir
    }

    /// [`soup`]'s triangles as leaf triangles (no normals).
    fn leaf_soup(n: usize, seed: u64) -> Vec<LeafTriangle> {
        let (p, t) = soup(n, seed);
        t.iter()
            .map(|tri| LeafTriangle {
                corners: tri.map(|v| p[v as usize]),
                normal: Vec3::ZERO,
            })
            .collect()
    }

    #[test]
    fn eight_triangle_test_matches_the_single_one() {
        if !Isa::detected().has_avx2() {
            eprintln!("note: no AVX2 here; the dispatched path is the scalar one, compared with itself");
        }
        let tris = leaf_soup(400, 21);
        let mut rnd = xorshift(23);
        let (mut hits, mut corner_hits) = (0, 0);
        for k in 0..600 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 20.0 - 5.0;
            let start = (k * 7) % (tris.len() - 8);
            let group = &tris[start..start + 1 + k % 8];
            let ray = ShearedRay::new(origin, aimed(origin, group[k % group.len()].corners, k, 11));
            let active = if k % 4 == 0 { 0xff } else { (k as u32 * 37) & 0xff };
            let (t_min, t_max) = if k % 5 == 0 { (0.3, 0.9) } else { (0.0, f32::INFINITY) };
            let (h8, t8) = ray.intersect8(group, active, t_min, t_max);
            let (h1, t1) = ray.intersect8_scalar(group, active, t_min, t_max);
            assert_eq!(h8, h1, "ray {k}");
            for i in 0..8 {
                if h1 & (1 << i) != 0 {
                    assert_eq!(t8[i].to_bits(), t1[i].to_bits(), "ray {k} lane {i}");
                }
            }
            hits += h1.count_ones();
            corner_hits += (k % 3 == 1 && h1 != 0) as u32;
        }
        assert!(hits > 100 && corner_hits > 20, "{hits} {corner_hits}");
        // Exact zeros: the ray through a shared corner and along a shared edge of a fan.
        let fan: Vec<LeafTriangle> = (0..6)
            .map(|i| {
                let a = i as f32 * std::f32::consts::TAU / 6.0;
                let b = a + std::f32::consts::TAU / 6.0;
                LeafTriangle {
                    corners: [
                        Vec3::new(0.0, 0.0, 5.0),
                        Vec3::new(a.cos(), a.sin(), 5.0),
                        Vec3::new(b.cos(), b.sin(), 5.0),
                    ],
                    normal: Vec3::ZERO,
                }
            })
            .collect();
        for origin in [Vec3::ZERO, Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.25, 0.0, -1.0)] {
            let ray = ShearedRay::new(origin, Vec3::Z);
            let (h8, t8) = ray.intersect8(&fan, 0xff, 0.0, f32::INFINITY);
            let (h1, t1) = ray.intersect8_scalar(&fan, 0xff, 0.0, f32::INFINITY);
            assert_eq!(h8, h1);
            assert!(h1 != 0, "the fan is hit at {origin}");
            for i in 0..6 {
                if h1 & (1 << i) != 0 {
                    assert_eq!(t8[i].to_bits(), t1[i].to_bits());
                }
            }
        }
    }

    /// The packet's leaf test gives each ray of its mask the bits and parameters of that ray's
    /// own `intersect8` (all eight lanes when there is AVX2; the scalar path otherwise), for
    /// leaves of 1 to 8 triangles, sparse masks, rays through corners, along edges and with
    /// zero direction components, and per-ray bounds.
    #[test]
    fn packet_leaf_test_is_each_rays_own() {
        let tris = leaf_soup(400, 29);
        let mut rnd = xorshift(31);
        let mut hits = 0;
        for k in 0..300 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 20.0 - 5.0;
            let start = (k * 7) % (tris.len() - 8);
            let leaf = &tris[start..start + 1 + k % 8];
            let rays: Vec<ShearedRay> = (0..64)
                .map(|r| ShearedRay::new(origin, aimed(origin, leaf[r % leaf.len()].corners, r, 13)))
                .collect();
            let mask = match k % 3 {
                0 => u64::MAX,
                1 => 0x8000_0001_0100_0010,
                _ => (k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
            };
            let t_max: Vec<f32> = (0..64).map(|r| if r % 4 == 0 { 0.6 } else { f32::INFINITY }).collect();
            let mut got = vec![(0u32, [0f32; 8]); 64];
            intersect8_packet(leaf, origin, &rays, mask, 0.0, &t_max, |r, h, ts| got[r] = (h, *ts));
            for r in 0..64 {
                let (h1, t1) = rays[r].intersect8(leaf, 0xff, 0.0, t_max[r]);
                let want = if mask & (1 << r) != 0 { h1 } else { 0 };
                assert_eq!(got[r].0, want, "leaf {k}, ray {r}");
                for (i, t) in t1.iter().enumerate() {
                    if want & (1 << i) != 0 {
                        assert_eq!(got[r].1[i].to_bits(), t.to_bits(), "leaf {k}, ray {r}, lane {i}");
                    }
                }
                hits += want.count_ones();
            }
        }
        assert!(hits > 2000, "{hits}");
    }

    /// The children's boxes the traversal derives from the parent's box are the stored ones.
    #[test]
    fn derived_children_are_the_stored_ones() {
        let (p, t) = soup(500, 11);
        // A flat layer too: its flat axis is not split.
        let flat: Vec<Vec3> = p.iter().map(|v| Vec3::new(v.x, 2.0, v.z)).collect();
        for pos in [&p, &flat] {
            let o = RayOctree::build_triangles(
                pos,
                &t,
                RayOctreeConfig {
                    max_depth: 6,
                    max_leaf_size: 4,
                },
            )
            .expect("a triangle soup builds");
            let mut internal = 0;
            for (n, node) in o.nodes().iter().enumerate() {
                if node.is_leaf() {
                    continue;
                }
                internal += 1;
                let si = o.split_info()[n];
                let h = halves(&node.bounds, si);
                for i in 0..8usize {
                    let c = &o.nodes()[node.first as usize + i];
                    assert_eq!(si & (1 << i) != 0, !(c.is_leaf() && c.count == 0));
                    if si & (1 << i) == 0 {
                        continue;
                    }
                    let pick = |a: usize| {
                        if i & (1 << a) != 0 {
                            (h[2][a], h[3][a])
                        } else {
                            (h[0][a], h[1][a])
                        }
                    };
                    let (x, y, z) = (pick(0), pick(1), pick(2));
                    assert_eq!(c.bounds.min, Vec3::new(x.0, y.0, z.0));
                    assert_eq!(c.bounds.max, Vec3::new(x.1, y.1, z.1));
                }
            }
            assert!(internal > 3);
        }
    }

    #[test]
    fn empty_tree_and_missing_ray() {
        let o = RayOctree::default();
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

    /// `candidates8`: the thin hits of `intersect8`, the scalar and AVX2 paths the same bits,
    /// and every triangle with a point within the radius of the ray marked close, with a
    /// corner parameter no more than the slack past that point's parameter. Triangles of every
    /// size, some edge-on, around rays of every direction.
    #[test]
    fn candidates_hold_every_triangle_within_the_radius() {
        let mut rnd = xorshift(31);
        let (mut near, mut far) = (0, 0);
        for k in 0..3000 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 20.0 - 10.0;
            let mut dir = Vec3::new(rnd(), rnd(), rnd()) * 2.0 - 1.0;
            if k % 7 == 0 {
                dir.y = 0.0;
            }
            let dir = dir * [1.0, 0.01, 30.0][k % 3];
            let sheared = ShearedRay::new(origin, dir);
            let (spread, margin) = [(1e-4, 1e-5), (3e-3, 0.0), (0.0, 0.2)][(k / 3) % 3];
            let radius = spread * 40.0 + margin;
            let scale = [0.02, 1.0, 20.0][(k / 9) % 3];
            let tris: Vec<LeafTriangle> = (0..8)
                .map(|j| {
                    // Around a point of the ray, often within a few radii of it.
                    let at = origin + dir * (rnd() * 40.0 / dir.length());
                    let off = (Vec3::new(rnd(), rnd(), rnd()) - 0.5) * radius * 6.0;
                    let mut c = [0; 3].map(|_| at + off + (Vec3::new(rnd(), rnd(), rnd()) - 0.5) * scale);
                    if j == 3 {
                        // Edge-on: the ray's direction lies in its plane.
                        c[2] = c[0] + dir * (rnd() * scale / dir.length());
                    }
                    LeafTriangle {
                        corners: c,
                        normal: (c[1] - c[0]).cross(c[2] - c[0]),
                    }
                })
                .collect();
            let active = 0xff >> (k % 3);
            // The parameters of lanes without a hit are unspecified.
            let hit_t = |hits: u32, t: [f32; 8]| {
                (
                    hits,
                    std::array::from_fn::<_, 8, _>(|i| (hits >> i & 1 != 0).then_some(t[i])),
                )
            };
            // A bound past every triangle, or among them (the cone's radius capped there).
            let t_max = [1e9, 25.0, 12.0][(k / 27) % 3];
            let got = sheared.candidates8(&tris, active, spread, margin, 0.0, t_max);
            let scalar = sheared.candidates8_scalar(&tris, active, spread, margin, 0.0, t_max);
            assert_eq!((got.close, got.t_reach), (scalar.close, scalar.t_reach), "ray {k}");
            assert_eq!(hit_t(got.hits, got.t), hit_t(scalar.hits, scalar.t), "ray {k}");
            let (hits, t) = sheared.intersect8(&tris, active, 0.0, t_max);
            assert_eq!(hit_t(got.hits, got.t), hit_t(hits, t), "ray {k}");
            let d = dir.as_dvec3().normalize();
            let o = origin.as_dvec3();
            for (i, tri) in tris.iter().enumerate().filter(|&(i, _)| active & (1 << i) != 0) {
                let c = tri.corners.map(|v| v.as_dvec3());
                // The point of a grid over the triangle deepest inside the cone: its distance
                // across the ray less the cone's radius there, and its parameter; `within`:
                // the same among the points no farther than the bound.
                let mut best = (f64::INFINITY, 0.0);
                let mut within = (f64::INFINITY, 0.0);
                for a in 0..=40 {
                    for b in 0..=(40 - a) {
                        let (wa, wb) = (a as f64 / 40.0, b as f64 / 40.0);
                        let p = c[0] + (c[1] - c[0]) * wa + (c[2] - c[0]) * wb;
                        let along = (p - o).dot(d);
                        let t = along / dir.as_dvec3().length();
                        let across = ((p - o) - d * along).length() - (spread as f64 * t.max(0.0) + margin as f64);
                        if across < best.0 {
                            best = (across, t);
                        }
                        if across < within.0 && (0.0..=t_max as f64).contains(&t) {
                            within = (across, t);
                        }
                    }
                }
                if within.0 <= 0.0 {
                    near += 1;
                    assert!(got.close & (1 << i) != 0, "ray {k}, triangle {i}: {within:?} not close");
                    assert!(
                        got.t_reach[i] as f64 <= within.1 + 1e-5 * within.1.abs(),
                        "ray {k}, triangle {i}: reached at {} past {within:?}",
                        got.t_reach[i]
                    );
                } else if best.0 > 3.0 * radius as f64 + 0.05 * scale as f64 {
                    far += (got.close & (1 << i) == 0) as u32;
                }
            }
        }
        // Some triangles near the ray, and most of those clearly away from it left out (the
        // test is not "everything is close").
        assert!(near > 2000, "{near}");
        assert!(far > 3000, "{far}");
    }
}
