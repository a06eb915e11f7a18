//! Triangle–box overlap.
//!
//! # References
//! - Akenine-Möller, "Fast 3D Triangle-Box Overlap Testing", JGT 6(1), 2001: the separating
//!   axis test over the box normals, the triangle normal and the nine edge cross products.

use crate::geom::Aabb;
use glam::Vec3;

/// True when the closed triangle and the closed box share a point (touching counts).
/// Exact up to floating-point rounding of the 13 axis projections. An empty box overlaps nothing.
pub fn tri_box_overlap(aabb: &Aabb, tri: [Vec3; 3]) -> bool {
    if aabb.is_empty() {
        return false;
    }
    let c = aabb.center();
    let h = aabb.half_extent();
    let v = [tri[0] - c, tri[1] - c, tri[2] - c];
    // Box normals: the triangle's bounds against the box.
    let lo = v[0].min(v[1]).min(v[2]);
    let hi = v[0].max(v[1]).max(v[2]);
    if lo.cmpgt(h).any() || hi.cmplt(-h).any() {
        return false;
    }
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    // Nine axes a_ij = e_box_i × e_j.
    for edge in e {
        for axis in [
            Vec3::new(0.0, -edge.z, edge.y),
            Vec3::new(edge.z, 0.0, -edge.x),
            Vec3::new(-edge.y, edge.x, 0.0),
        ] {
            let p0 = axis.dot(v[0]);
            let p1 = axis.dot(v[1]);
            let p2 = axis.dot(v[2]);
            let r = h.dot(axis.abs());
            if p0.min(p1).min(p2) > r || p0.max(p1).max(p2) < -r {
                return false;
            }
        }
    }
    // Triangle normal: plane–box test.
    let n = e[0].cross(e[1]);
    let r = h.dot(n.abs());
    let s = n.dot(v[0]);
    s.abs() <= r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> Aabb {
        Aabb::new(Vec3::ZERO, Vec3::ONE)
    }

    #[test]
    fn inside_touching_and_outside() {
        assert!(tri_box_overlap(
            &unit(),
            [Vec3::splat(0.2), Vec3::splat(0.3), Vec3::new(0.2, 0.5, 0.3)]
        ));
        assert!(tri_box_overlap(
            &unit(),
            [
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 1.0, 0.0)
            ]
        ));
        assert!(!tri_box_overlap(
            &unit(),
            [
                Vec3::new(1.1, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 1.0, 0.0)
            ]
        ));
        assert!(!tri_box_overlap(&Aabb::EMPTY, [Vec3::ZERO; 3]));
    }

    #[test]
    fn large_triangle_through_box_overlaps() {
        let t = [
            Vec3::new(-10.0, -10.0, 0.5),
            Vec3::new(10.0, -10.0, 0.5),
            Vec3::new(0.0, 10.0, 0.5),
        ];
        assert!(tri_box_overlap(&unit(), t));
    }

    #[test]
    fn diagonal_triangle_missing_the_corner_is_separated_by_an_edge_axis() {
        // Bounds overlap and the plane cuts the box, but an edge cross-product axis separates.
        let t = [
            Vec3::new(1.5, -0.5, 0.5),
            Vec3::new(2.5, 0.5, 0.5),
            Vec3::new(1.5, 0.5, 0.6),
        ];
        let brute = brute_force(&unit(), t);
        assert_eq!(tri_box_overlap(&unit(), t), brute);
    }

    /// Oracle: dense sampling of the triangle (only finds overlaps of positive measure).
    fn brute_force(b: &Aabb, t: [Vec3; 3]) -> bool {
        let n = 200;
        (0..=n).any(|i| {
            (0..=n - i).any(|j| {
                let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                b.contains_point(t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v)
            })
        })
    }

    #[test]
    fn agrees_with_sampling_on_random_triangles() {
        let mut s = 0x9e3779b97f4a7c15u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 * 3.0 - 1.0
        };
        for _ in 0..300 {
            let t = [
                Vec3::new(rnd(), rnd(), rnd()),
                Vec3::new(rnd(), rnd(), rnd()),
                Vec3::new(rnd(), rnd(), rnd()),
            ];
            // Sampling finds a subset of true overlaps: every sampled overlap must be reported.
            if brute_force(&unit(), t) {
                assert!(tri_box_overlap(&unit(), t), "{t:?}");
            }
        }
    }
}
