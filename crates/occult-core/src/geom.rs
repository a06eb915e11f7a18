//! Axis-aligned boxes, planes and frusta.

use glam::{Affine3A, Mat4, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// An axis-aligned box, `min` and `max` inclusive. The empty box has `min > max` on every axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box: the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The box spanning `min..=max`.
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// The smallest box holding all `points` (empty for no points).
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Self {
        points.into_iter().fold(Self::EMPTY, |b, p| b.including(p))
    }

    /// True when the box holds no point.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// This box grown to hold `p`.
    #[inline]
    pub fn including(self, p: Vec3) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    #[inline]
    pub fn union(self, other: Aabb) -> Self {
        Self {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The common part (possibly empty).
    pub fn intersection(self, other: Aabb) -> Self {
        Self {
            min: self.min.max(other.min),
            max: self.max.min(other.max),
        }
    }

    /// Centre point.
    #[inline]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the size along each axis.
    #[inline]
    pub fn half_extent(&self) -> Vec3 {
        (self.max - self.min) * 0.5
    }

    /// Size along each axis.
    #[inline]
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }

    /// Surface area (0 for an empty box).
    pub fn surface_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let s = self.size();
        2.0 * (s.x * s.y + s.y * s.z + s.z * s.x)
    }

    /// True when `p` lies inside or on the boundary.
    pub fn contains_point(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// True when the boxes share at least one point.
    pub fn overlaps(&self, other: &Aabb) -> bool {
        self.min.cmple(other.max).all() && other.min.cmple(self.max).all()
    }

    /// The 8 corners; corner `i` takes `max` on axis `a` when bit `a` of `i` is set.
    pub fn corners(&self) -> [Vec3; 8] {
        std::array::from_fn(|i| {
            Vec3::new(
                if i & 1 != 0 { self.max.x } else { self.min.x },
                if i & 2 != 0 { self.max.y } else { self.min.y },
                if i & 4 != 0 { self.max.z } else { self.min.z },
            )
        })
    }

    /// The box holding this box after an affine transform (exact for the transformed corners).
    pub fn transformed(&self, dst_from_src: &Affine3A) -> Aabb {
        if self.is_empty() {
            return *self;
        }
        Aabb::from_points(self.corners().into_iter().map(|c| dst_from_src.transform_point3(c)))
    }
}

/// A plane `normal · p + d = 0`; the positive side (`>= 0`) is "inside".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Normal (unit length when built by [`Plane::from_vec4`]).
    pub normal: Vec3,
    /// Offset.
    pub d: f32,
}

impl Plane {
    /// The plane `(v.x, v.y, v.z) · p + v.w = 0`, normalized. A zero normal gives a plane
    /// that holds everything (`normal = 0`, `d = 1`): it never culls.
    pub fn from_vec4(v: Vec4) -> Self {
        let len = v.truncate().length();
        if len > 0.0 && len.is_finite() {
            Self {
                normal: v.truncate() / len,
                d: v.w / len,
            }
        } else {
            Self {
                normal: Vec3::ZERO,
                d: 1.0,
            }
        }
    }

    /// Signed distance of `p` (positive inside).
    #[inline]
    pub fn distance(&self, p: Vec3) -> f32 {
        self.normal.dot(p) + self.d
    }
}

/// Where a volume lies relative to a frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Containment {
    /// Entirely outside one plane: culled.
    Outside,
    /// Crosses at least one plane.
    Intersects,
    /// Inside all planes.
    Inside,
}

/// A view frustum as six inward-facing planes (left, right, bottom, top, near, far), in the
/// space of whatever matrix it was built from. Build it with [`crate::View::frustum`], which
/// widens it by a guard margin so that culling is conservative with respect to the rasterizer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    /// Left, right, bottom, top, near, far.
    pub planes: [Plane; 6],
}

impl Frustum {
    /// The frustum of a reversed-Z infinite projection `clip_from_object` (clip `z` constant
    /// `= near`, `w` = view distance), cut at view distance `far`, in object space.
    /// `margin_ndc` widens the side planes (in NDC units, `2/width` is one pixel) and
    /// `depth_margin` moves near and far outwards by that fraction.
    pub fn from_reversed_z(clip_from_object: &Mat4, far: f32, margin_ndc: glam::Vec2, depth_margin: f32) -> Self {
        let m = clip_from_object.transpose(); // rows of clip_from_object as columns
        let (r0, r1, r2, r3) = (m.x_axis, m.y_axis, m.z_axis, m.w_axis);
        let sx = 1.0 + margin_ndc.x;
        let sy = 1.0 + margin_ndc.y;
        let far_plane = Vec4::new(0.0, 0.0, 0.0, far * (1.0 + depth_margin)) - r3;
        Frustum {
            planes: [
                Plane::from_vec4(r3 * sx + r0),
                Plane::from_vec4(r3 * sx - r0),
                Plane::from_vec4(r3 * sy + r1),
                Plane::from_vec4(r3 * sy - r1),
                // §near: w >= z_clip, z_clip = near; widened by moving the plane towards the eye.
                Plane::from_vec4(r3 - r2 * (1.0 - depth_margin)),
                Plane::from_vec4(far_plane),
            ],
        }
    }

    /// This frustum (of `clip_from_object`, as [`Frustum::from_reversed_z`] made it) with its
    /// side planes moved to `x_ndc = left`, `x_ndc = right`, `y_ndc = bottom` and
    /// `y_ndc = top`, where given: a region of the screen.
    pub fn with_ranges(mut self, clip_from_object: &Mat4, [left, right, bottom, top]: [Option<f32>; 4]) -> Self {
        let m = clip_from_object.transpose();
        let (r0, r1, r3) = (m.x_axis, m.y_axis, m.w_axis);
        if let Some(l) = left {
            self.planes[0] = Plane::from_vec4(r0 - r3 * l);
        }
        if let Some(r) = right {
            self.planes[1] = Plane::from_vec4(r3 * r - r0);
        }
        if let Some(b) = bottom {
            self.planes[2] = Plane::from_vec4(r1 - r3 * b);
        }
        if let Some(t) = top {
            self.planes[3] = Plane::from_vec4(r3 * t - r1);
        }
        self
    }

    /// Classifies a box by the centre–extent test against each plane. Conservative: a box
    /// reported `Outside` lies outside one plane entirely.
    #[inline]
    pub fn classify_aabb(&self, aabb: &Aabb) -> Containment {
        let c = aabb.center();
        let e = aabb.half_extent();
        let mut result = Containment::Inside;
        for p in &self.planes {
            let s = p.normal.dot(c) + p.d;
            let r = p.normal.abs().dot(e);
            if s + r < 0.0 {
                return Containment::Outside;
            }
            if s - r < 0.0 {
                result = Containment::Intersects;
            }
        }
        result
    }

    /// True unless the box is entirely outside one plane.
    #[inline]
    pub fn intersects_aabb(&self, aabb: &Aabb) -> bool {
        !aabb.is_empty() && self.classify_aabb(aabb) != Containment::Outside
    }

    /// True unless the sphere is entirely outside one plane (planes are unit length).
    pub fn intersects_sphere(&self, center: Vec3, radius: f32) -> bool {
        self.planes.iter().all(|p| p.distance(center) >= -radius)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_box_is_union_identity() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert!(Aabb::EMPTY.is_empty());
        assert_eq!(Aabb::EMPTY.union(b), b);
        assert_eq!(Aabb::from_points([]), Aabb::EMPTY);
    }

    #[test]
    fn corners_and_transform() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(b.corners()[7], Vec3::ONE);
        let t = Affine3A::from_translation(Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(
            b.transformed(&t),
            Aabb::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(2.0, 3.0, 4.0))
        );
        assert!(Aabb::EMPTY.transformed(&t).is_empty());
    }

    #[test]
    fn plane_with_zero_normal_never_culls() {
        let p = Plane::from_vec4(Vec4::ZERO);
        assert!(p.distance(Vec3::splat(1e9)) > 0.0);
    }
}
