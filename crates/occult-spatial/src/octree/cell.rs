//! Cell arithmetic and configuration rules shared by the three octrees.
//!
//! Conventions, fixed once for [`super::ray`], [`super::hybrid`] and [`super::sample`]:
//! - A cell is split at one point (its centre) into 8 octants; octant `i` takes the upper half
//!   on axis `a` when bit `a` of `i` is set ([`octant_of`], [`child_bounds`], [`child_min`]).
//!   A point on a splitting plane belongs to the upper half.
//! - Depth counts the halvings below the root; no octree goes deeper than [`MAX_OCTREE_DEPTH`].
//!   A build stops splitting a cell at its leaf size or at its depth limit ([`stops_splitting`]).
//! - A configuration is checked before anything is built, by the same rules in every octree
//!   ([`check_leaf_size`], [`check_depth`], [`check_fraction`]); a value out of range is an
//!   [`OctreeConfigError`] naming the field and the value, never clamped.

use occult_core::{Aabb, Vec3};

/// Deepest level any octree accepts, counted in halvings of the root cell (the root is level 0).
///
/// Twice the 24 bits of an `f32` mantissa: a cell halved more often than that is below the
/// resolution of any coordinate it could bound, so a deeper limit only guards against
/// coincident primitives (the sample octree's default, a guard of exactly this depth, sets the
/// value). Renderers document narrower ranges of their own where their structures need them.
pub const MAX_OCTREE_DEPTH: u32 = 48;

/// A configuration value out of range: the field, the value given and the range accepted.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("bad octree configuration: {field}={value} is not in {expected}")]
pub struct OctreeConfigError {
    /// The configuration field, as the config type names it.
    pub field: &'static str,
    /// The value given, as text.
    pub value: String,
    /// The accepted range, as text.
    pub expected: String,
}

impl OctreeConfigError {
    fn new(field: &'static str, value: impl std::fmt::Display, expected: impl std::fmt::Display) -> Self {
        Self {
            field,
            value: value.to_string(),
            expected: expected.to_string(),
        }
    }
}

/// Checks a leaf size: at least 1 primitive. There is no upper bound: a leaf size at or above
/// the primitive count only makes the root a leaf.
///
/// # Errors
/// [`OctreeConfigError`] naming `field` for 0.
pub fn check_leaf_size(field: &'static str, value: usize) -> Result<(), OctreeConfigError> {
    if value >= 1 {
        Ok(())
    } else {
        Err(OctreeConfigError::new(field, value, "1.."))
    }
}

/// Checks a depth limit: `min..=`[`MAX_OCTREE_DEPTH`] (`min` is 0 for a limit in halvings, 1
/// for one in levels with the root as level 1).
///
/// # Errors
/// [`OctreeConfigError`] naming `field` for a value out of that range.
pub fn check_depth(field: &'static str, value: u32, min: u32) -> Result<(), OctreeConfigError> {
    if (min..=MAX_OCTREE_DEPTH).contains(&value) {
        Ok(())
    } else {
        Err(OctreeConfigError::new(
            field,
            value,
            format_args!("{min}..={MAX_OCTREE_DEPTH}"),
        ))
    }
}

/// Checks a finite value in `min..=max` (NaN and infinities are out of range; `max` may be
/// [`f32::MAX`] for no upper bound).
///
/// # Errors
/// [`OctreeConfigError`] naming `field` for a value out of that range.
pub fn check_fraction(field: &'static str, value: f32, min: f32, max: f32) -> Result<(), OctreeConfigError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(())
    } else if max == f32::MAX {
        Err(OctreeConfigError::new(
            field,
            value,
            format_args!("finite values >= {min}"),
        ))
    } else {
        Err(OctreeConfigError::new(field, value, format_args!("{min}..={max}")))
    }
}

/// True when a cell holding `count` primitives at `depth` stays a leaf: at most `leaf_size`
/// primitives, or at the depth limit `max_depth` (both in the caller's own depth unit).
#[inline]
pub fn stops_splitting(count: usize, leaf_size: usize, depth: u32, max_depth: u32) -> bool {
    count <= leaf_size || depth >= max_depth
}

/// The octant of `p` in a cell split at `center`: bit `a` set when `p[a] >= center[a]`.
#[inline]
pub fn octant_of(center: Vec3, p: Vec3) -> usize {
    (p.x >= center.x) as usize | ((p.y >= center.y) as usize) << 1 | ((p.z >= center.z) as usize) << 2
}

/// Per axis `a`, `upper[a]` when bit `a` of `octant` is set, else `lower[a]`.
#[inline]
pub fn select(octant: usize, lower: Vec3, upper: Vec3) -> Vec3 {
    Vec3::new(
        if octant & 1 != 0 { upper.x } else { lower.x },
        if octant & 2 != 0 { upper.y } else { lower.y },
        if octant & 4 != 0 { upper.z } else { lower.z },
    )
}

/// The minimum corner of octant `octant` of the cell whose minimum corner is `min` and whose
/// centre is `center`.
#[inline]
pub fn child_min(min: Vec3, center: Vec3, octant: usize) -> Vec3 {
    select(octant, min, center)
}

/// The box of octant `octant` of `parent` split at `split`: `parent.min..split` on the axes
/// where the octant's bit is clear, `split..parent.max` where it is set.
#[inline]
pub fn child_bounds(parent: &Aabb, split: Vec3, octant: usize) -> Aabb {
    Aabb::new(select(octant, parent.min, split), select(octant, split, parent.max))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octants_tile_the_parent() {
        let b = Aabb::new(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(3.0, 2.0, 6.0));
        let c = b.center();
        let mut volume = 0.0;
        for o in 0..8 {
            let k = child_bounds(&b, c, o);
            assert_eq!(octant_of(c, k.center()), o);
            assert_eq!(child_min(b.min, c, o), k.min);
            volume += k.size().x * k.size().y * k.size().z;
        }
        assert_eq!(volume, b.size().x * b.size().y * b.size().z);
        // A point on a splitting plane is in the upper half.
        assert_eq!(octant_of(c, c), 7);
        assert_eq!(octant_of(c, Vec3::new(f32::NAN, 5.0, 0.0)), 2);
    }

    #[test]
    fn every_rule_names_the_field_and_value() {
        assert!(check_leaf_size("leaf_size", 1).is_ok() && check_leaf_size("leaf_size", usize::MAX).is_ok());
        let e = check_leaf_size("leaf_size", 0).unwrap_err();
        assert_eq!((e.field, e.value.as_str()), ("leaf_size", "0"));
        assert!(e.to_string().contains("leaf_size=0"), "{e}");
        assert!(check_depth("max_depth", 0, 0).is_ok());
        assert!(check_depth("max_depth", 0, 1).is_err());
        assert!(check_depth("max_depth", MAX_OCTREE_DEPTH, 1).is_ok());
        let e = check_depth("max_depth", MAX_OCTREE_DEPTH + 1, 0).unwrap_err();
        assert_eq!(e.value, (MAX_OCTREE_DEPTH + 1).to_string());
        for bad in [f32::NAN, f32::INFINITY, -0.5, 1.5] {
            assert!(check_fraction("small_fraction", bad, 0.0, 1.0).is_err(), "{bad}");
        }
        assert!(check_fraction("small_fraction", 0.0, 0.0, 1.0).is_ok());
        assert!(check_fraction("extension", 7.0, 0.0, f32::MAX).is_ok());
        assert!(check_fraction("extension", f32::INFINITY, 0.0, f32::MAX).is_err());
        assert!(stops_splitting(4, 4, 0, 8) && stops_splitting(9, 4, 8, 8) && !stops_splitting(5, 4, 7, 8));
    }
}
