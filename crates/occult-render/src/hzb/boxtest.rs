//! The hierarchical box-face occlusion test of §3.2, and screen rectangles of boxes.
//!
//! Margins are those of [`occult_raster::query_box`], which the rasterizer's own tests hold
//! conservative: depth ×(1 + 1e-5) for rounding, 1/64 pixel for vertex snapping (1/256 px), and
//! any corner at or in front of the near plane (within 1e-5) makes a box untestable (visible).

use occult_core::{Aabb, Mat4, Vec3, Vec4};
use occult_raster::{Frame, PixelRect, PyramidCounts, PyramidTest, ZPyramid};

/// Pixel margin for vertex snapping.
const SNAP_MARGIN: f64 = 1.0 / 64.0;
/// Relative depth margin for the rasterizer's rounding.
const DEPTH_MARGIN: f32 = 1e-5;
/// Boxes at most this wide and tall on screen, pixels, are tested whole (Greene), not face by
/// face (Georges §3.2).
const WHOLE_BOX_PIXELS: f64 = 16.0;

/// The 8 clip-space corners of `b` (corner `i` takes `max` on axis `a` when bit `a` is set), or
/// None when one is not finite or reaches the near plane: such a box may cover anything.
#[inline]
fn clip_corners(clip_from_object: &Mat4, b: &Aabb) -> Option<[Vec4; 8]> {
    let c = b.corners().map(|p| *clip_from_object * p.extend(1.0));
    for v in &c {
        if !v.is_finite() || v.z * (1.0 + DEPTH_MARGIN) > v.w {
            return None;
        }
    }
    Some(c)
}

/// A corner's position on screen, pixels (`x` right, `y` down), for a `w × h` frame.
#[inline]
fn screen_xy(v: Vec4, w: f64, h: f64) -> (f64, f64) {
    let cw = v.w as f64;
    ((v.x as f64 / cw * 0.5 + 0.5) * w, (0.5 - v.y as f64 / cw * 0.5) * h)
}

/// `ceil(x)` clamped to `[0, hi]` (`hi` a whole number below 2^31; NaN gives 0), as
/// `x.ceil().clamp(0.0, hi) as u32` computes it, without the library call that `f64::ceil` is
/// on the baseline instruction set (a box test makes four).
#[inline]
fn ceil_clamped(x: f64, hi: f64) -> u32 {
    let v = x.clamp(0.0, hi);
    let i = v as u32; // truncation: the floor of a value in [0, hi]; NaN → 0
    if f64::from(i) < v {
        i + 1
    } else {
        i
    }
}

/// `floor(x) + 1` clamped to `[0, hi]`, as `(x.floor() + 1.0).clamp(0.0, hi) as u32` computes
/// it (see [`ceil_clamped`]).
#[inline]
fn floor_plus_one_clamped(x: f64, hi: f64) -> u32 {
    if x.is_nan() || x <= -1.0 {
        return 0; // at most -1, or NaN
    }
    let v = x.min(hi);
    let t = v as i64; // truncation toward zero
    let floor = if t as f64 > v { t - 1 } else { t };
    (floor + 1).clamp(0, hi as i64) as u32
}

/// The pixels whose centres a projection spanning `[minx, maxx] × [miny, maxy]` (pixels) may
/// reach (empty rectangle when none), for a `w × h` frame.
#[inline]
fn rect_of_span(minx: f64, maxx: f64, miny: f64, maxy: f64, w: f64, h: f64) -> PixelRect {
    PixelRect {
        x0: ceil_clamped(minx - SNAP_MARGIN - 0.5, w),
        y0: ceil_clamped(miny - SNAP_MARGIN - 0.5, h),
        x1: floor_plus_one_clamped(maxx + SNAP_MARGIN - 0.5, w),
        y1: floor_plus_one_clamped(maxy + SNAP_MARGIN - 0.5, h),
    }
}

/// The pixels whose centres the projection of the given corners may reach (empty rectangle
/// when none), for a `width × height` frame.
#[inline]
fn rect_of(c: &[Vec4; 8], corners: impl Iterator<Item = usize>, width: u32, height: u32) -> PixelRect {
    let (w, h) = (width as f64, height as f64);
    let (mut minx, mut maxx, mut miny, mut maxy) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for i in corners {
        let (x, y) = screen_xy(c[i], w, h);
        minx = minx.min(x);
        maxx = maxx.max(x);
        miny = miny.min(y);
        maxy = maxy.max(y);
    }
    rect_of_span(minx, maxx, miny, maxy, w, h)
}

/// The screen rectangle `b` may draw into (the whole frame when it reaches the near plane);
/// None for an empty box or an empty rectangle.
pub(crate) fn screen_rect(clip_from_object: &Mat4, b: &Aabb, width: u32, height: u32) -> Option<PixelRect> {
    if b.is_empty() {
        return None;
    }
    let r = match clip_corners(clip_from_object, b) {
        None => PixelRect {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        },
        Some(c) => rect_of(&c, 0..8, width, height),
    };
    (r.x0 < r.x1 && r.y0 < r.y1).then_some(r)
}

/// Where the test is run and what it counts.
pub(crate) struct Occlusion<'a> {
    pub frame: &'a Frame,
    pub pyramid: &'a ZPyramid,
    pub how: PyramidTest,
    pub far_depth: f32,
}

impl<'a> Occlusion<'a> {
    /// The full test (the global farthest depth, then the pyramid) of `frame` through
    /// `pyramid`, for `view`'s far plane.
    pub fn hierarchical(frame: &'a Frame, pyramid: &'a ZPyramid, view: &occult_core::View) -> Self {
        Self {
            frame,
            pyramid,
            how: PyramidTest {
                global: true,
                hierarchical: true,
            },
            far_depth: view.far_depth(),
        }
    }

    /// What both tests settle before any pyramid read: `Err(hidden)` for an empty box
    /// (hidden), one holding the eye or reaching the near plane (not hidden); else the box's
    /// clip-space corners.
    fn testable(clip_from_object: &Mat4, b: &Aabb, eye: Vec3) -> Result<[Vec4; 8], bool> {
        if b.is_empty() {
            return Err(true);
        }
        // An eye inside (or on, up to rounding) the box sees it from within.
        let slack = b.size() * 1e-4 + Vec3::splat(1e-6);
        if (eye.cmpge(b.min - slack) & eye.cmple(b.max + slack)).all() {
            return Err(false);
        }
        clip_corners(clip_from_object, b).ok_or(false)
    }

    /// §3.2: true when the box `b` (object space, placed by `clip_from_object`, the eye at `eye`
    /// in object space) is hidden behind what is drawn: every front face of the box is hidden
    /// over its screen box, compared at the face's nearest corner; a box at most
    /// `WHOLE_BOX_PIXELS` wide and tall on screen is tested whole instead, as
    /// [`Occlusion::whole_box_query`] and [`Occlusion::rect_hidden`] do. An empty box is hidden; a box
    /// holding the eye or reaching the near plane is not.
    pub fn box_hidden(&self, clip_from_object: &Mat4, b: &Aabb, eye: Vec3, counts: &mut PyramidCounts) -> bool {
        let c = match Self::testable(clip_from_object, b, eye) {
            Ok(c) => c,
            Err(hidden) => return hidden,
        };
        let (w, h) = (self.frame.width() as f64, self.frame.height() as f64);
        // Each corner projected once (screen position and depth), shared by the faces it is on.
        let xy = c.map(|v| screen_xy(v, w, h));
        let depth = c.map(|v| v.z / v.w);
        // A box small on screen: Greene's whole-box test (one rectangle at the nearest depth of
        // all corners) culls about as much as one test per face, for one pyramid test.
        let (mut minx, mut maxx, mut miny, mut maxy) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for &(x, y) in &xy {
            minx = minx.min(x);
            maxx = maxx.max(x);
            miny = miny.min(y);
            maxy = maxy.max(y);
        }
        if maxx - minx <= WHOLE_BOX_PIXELS && maxy - miny <= WHOLE_BOX_PIXELS {
            let nearest = depth.iter().copied().fold(0.0f32, f32::max) * (1.0 + DEPTH_MARGIN);
            if nearest < self.far_depth * (1.0 - DEPTH_MARGIN) {
                return true; // beyond the far plane: draws nothing
            }
            let r = rect_of_span(minx, maxx, miny, maxy, w, h);
            return self.pyramid.occludes(self.frame, r, nearest, self.how, counts);
        }
        // Front faces: the eye is strictly outside the face's plane. Their projections cover the
        // box's silhouette, and every point of the box lies behind a point of one of them.
        for axis in 0..3 {
            for high in [false, true] {
                let front = if high {
                    eye[axis] > b.max[axis]
                } else {
                    eye[axis] < b.min[axis]
                };
                if !front {
                    continue;
                }
                let bit = 1usize << axis;
                let (mut nearest, mut minx, mut maxx, mut miny, mut maxy) = (
                    0.0f32,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                );
                for i in (0..8).filter(|i| (i & bit != 0) == high) {
                    nearest = nearest.max(depth[i]);
                    let (x, y) = xy[i];
                    minx = minx.min(x);
                    maxx = maxx.max(x);
                    miny = miny.min(y);
                    maxy = maxy.max(y);
                }
                let nearest = nearest * (1.0 + DEPTH_MARGIN);
                if nearest < self.far_depth * (1.0 - DEPTH_MARGIN) {
                    continue; // beyond the far plane: draws nothing
                }
                let r = rect_of_span(minx, maxx, miny, maxy, w, h);
                if !self.pyramid.occludes(self.frame, r, nearest, self.how, counts) {
                    return false;
                }
            }
        }
        true
    }
}

impl Occlusion<'_> {
    /// [`Occlusion::whole_box_query`] and [`Occlusion::rect_hidden`] in one call.
    #[cfg(test)]
    pub fn box_hidden_whole(&self, clip_from_object: &Mat4, b: &Aabb, eye: Vec3, counts: &mut PyramidCounts) -> bool {
        match self.whole_box_query(clip_from_object, b, eye) {
            Ok((r, nearest)) => self.rect_hidden(r, nearest, counts),
            Err(hidden) => hidden,
        }
    }

    /// Greene's test of the box `b` as a whole, its first half: the box is hidden when its
    /// screen rectangle (over all eight corners) is hidden at the box's nearest depth
    /// ([`Occlusion::rect_hidden`], the second half). One pyramid test where
    /// [`Occlusion::box_hidden`] makes one per front face: cheaper, and as tight for a box
    /// small on screen (a cluster); looser for a large box seen at an angle, whose nearest
    /// corner then stands for faces that lie far behind it.
    ///
    /// Returns the rectangle and the nearest depth, or `Err` with the answer where no pyramid
    /// test is needed, with `box_hidden`'s margins and untestable boxes: an empty box or one
    /// beyond the far plane is hidden; one holding the eye or with a corner at the near plane
    /// is not. The rectangle and depth do not depend on the pyramid, so a box can be asked
    /// about again, after more is drawn, by `rect_hidden` alone.
    pub fn whole_box_query(&self, clip_from_object: &Mat4, b: &Aabb, eye: Vec3) -> Result<(PixelRect, f32), bool> {
        let c = Self::testable(clip_from_object, b, eye)?;
        let nearest = c.iter().map(|v| v.z / v.w).fold(0.0f32, f32::max) * (1.0 + DEPTH_MARGIN);
        if nearest < self.far_depth * (1.0 - DEPTH_MARGIN) {
            return Err(true); // beyond the far plane: draws nothing
        }
        Ok((rect_of(&c, 0..8, self.frame.width(), self.frame.height()), nearest))
    }

    /// Whether every pixel of `r` holds a depth nearer than `nearest` as the pyramid stands
    /// (a query of [`Occlusion::whole_box_query`]).
    pub fn rect_hidden(&self, r: PixelRect, nearest: f32, counts: &mut PyramidCounts) -> bool {
        self.pyramid.occludes(self.frame, r, nearest, self.how, counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inline_rounding_is_the_library_rounding() {
        let w = 1280.0;
        let mut xs = vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -0.0,
            0.0,
            w,
            w + 0.5,
            1e12,
            -1e12,
        ];
        for k in -40..=1320 * 4 {
            let x = k as f64 / 4.0;
            xs.extend([x, x.next_up(), x.next_down(), x + 1e-9, x - 1e-9]);
        }
        for x in xs {
            assert_eq!(ceil_clamped(x, w), x.ceil().clamp(0.0, w) as u32, "ceil of {x}");
            assert_eq!(
                floor_plus_one_clamped(x, w),
                (x.floor() + 1.0).clamp(0.0, w) as u32,
                "floor of {x}"
            );
        }
    }

    #[test]
    fn rect_covers_query_box_pixels() {
        let (view, clip) = crate::test_view(Vec3::new(0.3, 0.2, 5.0), Vec3::ZERO, 64, 48);
        let frame = Frame::new(64, 48).expect("a 64x48 frame");
        for b in [
            Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)),
            Aabb::new(Vec3::new(2.0, 1.0, -3.0), Vec3::new(2.5, 1.2, -2.0)),
        ] {
            let r = screen_rect(&clip, &b, 64, 48).expect("a box in view has a screen rectangle");
            let all = occult_raster::query_box(&frame, &view, &clip, &b);
            assert_eq!(occult_raster::query_rect(&frame, r, 1.0), r.area());
            assert!(all <= r.area());
        }
        // Near-crossing: the whole frame; empty box: nothing.
        let b = Aabb::new(Vec3::new(0.0, 0.0, 4.95), Vec3::new(1.0, 1.0, 6.0));
        assert_eq!(
            screen_rect(&clip, &b, 64, 48)
                .expect("a box through the near plane covers the screen")
                .area(),
            64 * 48
        );
        assert!(screen_rect(&clip, &Aabb::EMPTY, 64, 48).is_none());
    }

    /// The whole-box test is never looser than the face test: its rectangle holds every
    /// face's and its depth is the nearest of them all. It hides boxes behind a wall too.
    #[test]
    fn whole_box_test_implies_the_face_test() {
        let eye = Vec3::new(0.2, 0.3, 6.0);
        let (view, clip) = crate::test_view(eye, Vec3::ZERO, 64, 48);
        let mut frame = Frame::new(64, 48).expect("a 64x48 frame");
        // A wall at varying depth with holes.
        for y in 0..48 {
            for x in 0..64 {
                if (x * 7 + y * 3) % 23 != 0 {
                    frame.write_fragment(x, y, 0.08 + 0.001 * ((x + y) % 9) as f32, 1);
                }
            }
        }
        let mut pyramid = ZPyramid::new(64, 48).expect("a 64x48 pyramid");
        pyramid.rebuild(&frame);
        let o = Occlusion {
            frame: &frame,
            pyramid: &pyramid,
            how: PyramidTest {
                global: true,
                hierarchical: true,
            },
            far_depth: view.far_depth(),
        };
        let mut counts = PyramidCounts::default();
        let mut whole_hidden = 0;
        for i in 0..2000u32 {
            let f = |k: u32| ((i.wrapping_mul(2654435761).wrapping_add(k * 40503)) % 1000) as f32 / 1000.0;
            let min = Vec3::new(f(1) * 8.0 - 4.0, f(2) * 6.0 - 3.0, f(3) * 10.0 - 8.0);
            let b = Aabb::new(min, min + Vec3::new(f(4), f(5), f(6)) * 1.5);
            let whole = o.box_hidden_whole(&clip, &b, eye, &mut counts);
            assert!(!whole || o.box_hidden(&clip, &b, eye, &mut counts), "box {b:?}");
            whole_hidden += u32::from(whole);
        }
        assert!(whole_hidden > 100, "{whole_hidden} boxes hidden");
        assert!(o.box_hidden_whole(&clip, &Aabb::EMPTY, eye, &mut counts));
        let around_eye = Aabb::new(eye - Vec3::ONE, eye + Vec3::ONE);
        assert!(!o.box_hidden_whole(&clip, &around_eye, eye, &mut counts));
    }

    #[test]
    fn hidden_only_behind_a_full_wall() {
        let (view, clip) = crate::test_view(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, 32, 32);
        let mut frame = Frame::new(32, 32).expect("a 32x32 frame");
        let mut pyramid = ZPyramid::new(32, 32).expect("a 32x32 pyramid");
        let eye = Vec3::new(0.0, 0.0, 5.0);
        let b = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
        let mut counts = PyramidCounts::default();
        let how = PyramidTest {
            global: true,
            hierarchical: true,
        };
        let test = |frame: &Frame, pyramid: &ZPyramid, eye: Vec3, counts: &mut PyramidCounts| {
            Occlusion {
                frame,
                pyramid,
                how,
                far_depth: view.far_depth(),
            }
            .box_hidden(&clip, &b, eye, counts)
        };
        assert!(!test(&frame, &pyramid, eye, &mut counts));
        // A wall at distance 1 (depth 0.1) in front of the box (nearest depth 0.1/4.5).
        for y in 0..32 {
            for x in 0..32 {
                frame.write_fragment(x, y, 0.1, 7);
            }
        }
        pyramid.rebuild(&frame);
        assert!(test(&frame, &pyramid, eye, &mut counts));
        // The eye inside the box: never hidden.
        assert!(!test(&frame, &pyramid, Vec3::ZERO, &mut counts));
        // An empty box: hidden.
        let o = Occlusion {
            frame: &frame,
            pyramid: &pyramid,
            how,
            far_depth: view.far_depth(),
        };
        assert!(o.box_hidden(&clip, &Aabb::EMPTY, eye, &mut counts));
    }
}
