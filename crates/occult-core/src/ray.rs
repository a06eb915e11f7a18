//! Rays and the watertight ray–triangle test.
//!
//! # References
//! - Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013: the shear
//!   transform and the double-precision fallback for edge functions that round to zero.

use crate::geom::Aabb;
use glam::Vec3;

/// A ray `origin + t · direction`, `t` in `[t_min, t_max]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (need not be unit length; `t` is in its units).
    pub direction: Vec3,
    /// Smallest accepted `t`.
    pub t_min: f32,
    /// Largest accepted `t`.
    pub t_max: f32,
}

/// A hit: parameter and barycentrics of corners 1 and 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weight of the second corner.
    pub u: f32,
    /// Barycentric weight of the third corner.
    pub v: f32,
}

impl Ray {
    /// A ray over `[0, ∞)`.
    pub fn new(origin: Vec3, direction: Vec3) -> Self {
        Self {
            origin,
            direction,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    /// Point at `t`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }

    /// Entry and exit parameters of the slab test against `aabb`, clipped to the ray's range;
    /// `None` when it misses. Robust to zero direction components (IEEE infinities).
    pub fn intersect_aabb(&self, aabb: &Aabb) -> Option<(f32, f32)> {
        let inv = self.direction.recip();
        let t0 = (aabb.min - self.origin) * inv;
        let t1 = (aabb.max - self.origin) * inv;
        // NaN (0 · ∞) arises only when the origin lies on a slab plane with a zero direction
        // component; min/max then ignore it, which keeps the test conservative.
        let near = t0.min(t1).max_element().max(self.t_min);
        let far = t0.max(t1).min_element().min(self.t_max);
        (near <= far).then_some((near, far))
    }
}

/// Watertight ray–triangle intersection (Woop et al. 2013). Hits on shared edges are reported
/// for at least one of the triangles sharing the edge; both faces are hit (no culling).
pub fn intersect_ray_triangle(ray: &Ray, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<RayHit> {
    let d = ray.direction;
    // Woop §2: permute axes so that z is the dominant direction component.
    let kz = d.abs().max_position();
    let mut kx = (kz + 1) % 3;
    let mut ky = (kx + 1) % 3;
    if d[kz] < 0.0 {
        std::mem::swap(&mut kx, &mut ky);
    }
    let sx = d[kx] / d[kz];
    let sy = d[ky] / d[kz];
    let sz = 1.0 / d[kz];
    let a = p0 - ray.origin;
    let b = p1 - ray.origin;
    let c = p2 - ray.origin;
    let ax = a[kx] - sx * a[kz];
    let ay = a[ky] - sy * a[kz];
    let bx = b[kx] - sx * b[kz];
    let by = b[ky] - sy * b[kz];
    let cx = c[kx] - sx * c[kz];
    let cy = c[ky] - sy * c[kz];
    let (u, v, w, det) = sheared_edge_functions([ax, ay], [bx, by], [cx, cy])?;
    let az = sz * a[kz];
    let bz = sz * b[kz];
    let cz = sz * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    let inv_det = 1.0 / det;
    let t = t_scaled * inv_det;
    if !(t >= ray.t_min && t <= ray.t_max) {
        return None;
    }
    Some(RayHit {
        t,
        u: v * inv_det,
        v: w * inv_det,
    })
}

/// Woop et al. §2–3, the part after the shear: the edge functions `(u, v, w)` of a triangle
/// whose corners, relative to the ray's origin and sheared so that the ray runs along +z, have
/// the (x, y) coordinates `a`, `b`, `c`, and their sum `det`. `None` when the ray misses the
/// triangle (edge functions of both signs) or sees it edge-on (`det` 0). An edge function that
/// rounds to zero is recomputed in double precision (§3), which is what makes the test
/// watertight. Shared by [`intersect_ray_triangle`] and callers that shear once per ray.
#[inline]
pub fn sheared_edge_functions(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> Option<(f32, f32, f32, f32)> {
    let ([ax, ay], [bx, by], [cx, cy]) = (a, b, c);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    // Woop §3: recompute in double precision when an edge function rounds to zero.
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let (ax, ay, bx, by, cx, cy) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
        u = (cx * by - cy * bx) as f32;
        v = (ax * cy - ay * cx) as f32;
        w = (bx * ay - by * ax) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    (det != 0.0).then_some((u, v, w, det))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_center_and_misses_outside() {
        let r = Ray::new(Vec3::new(0.25, 0.25, 1.0), Vec3::new(0.0, 0.0, -1.0));
        let h = intersect_ray_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::Y).expect("the ray hits the triangle's interior");
        assert!((h.t - 1.0).abs() < 1e-6);
        let r = Ray::new(Vec3::new(1.25, 0.25, 1.0), Vec3::new(0.0, 0.0, -1.0));
        assert!(intersect_ray_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::Y).is_none());
    }

    #[test]
    fn shared_edge_is_never_missed() {
        // Two triangles sharing the diagonal of the unit square; rays along the diagonal.
        let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y);
        for i in 0..1000 {
            let s = i as f32 / 1000.0;
            let r = Ray::new(Vec3::new(s, s, 1.0), Vec3::new(0.0, 0.0, -1.0));
            let hit = intersect_ray_triangle(&r, a, b, c).is_some() || intersect_ray_triangle(&r, a, c, d).is_some();
            assert!(hit, "ray at {s} fell through the shared edge");
        }
    }

    #[test]
    fn degenerate_triangle_is_missed_and_behind_is_missed() {
        let r = Ray::new(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0));
        assert!(intersect_ray_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::X * 2.0).is_none());
        let r = Ray::new(Vec3::new(0.25, 0.25, -1.0), Vec3::new(0.0, 0.0, -1.0));
        assert!(intersect_ray_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::Y).is_none());
    }

    #[test]
    fn slab_test() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let r = Ray::new(Vec3::new(0.5, 0.5, 5.0), Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(r.intersect_aabb(&b), Some((4.0, 5.0)));
        let r = Ray::new(Vec3::new(2.0, 0.5, 5.0), Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(r.intersect_aabb(&b), None);
    }
}
