//! The hierarchical box-face occlusion test of §3.2, and screen rectangles of boxes.
//!
//! Margins are those of [`occult_raster::query_box`], which the rasterizer's own tests hold
//! conservative: depth ×(1 + 1e-5) for rounding, 1/64 pixel for vertex snapping (1/256 px), and
//! any corner at or in front of the near plane (within 1e-5) makes a box untestable (visible).

use occult_core::simd::Isa;
#[cfg(target_arch = "x86_64")]
use occult_core::simd::{Avx2, F32x8, F64x4, M32x8};
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
/// None when one is not finite, reaches the near plane or does not lie in front of the eye
/// (`w > 0`; with the crate's affine placements and projections, a corner behind the near
/// plane's margin always has `w ≥ near > 0`): such a box may cover anything.
#[inline]
fn clip_corners(clip_from_object: &Mat4, b: &Aabb) -> Option<[Vec4; 8]> {
    let c = b.corners().map(|p| *clip_from_object * p.extend(1.0));
    for v in &c {
        if !v.is_finite() || v.z * (1.0 + DEPTH_MARGIN) > v.w || v.w <= 0.0 {
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

/// A box's eight corners projected for a frame: screen positions in pixels ([`screen_xy`]) and
/// depths (`z / w`), corner `i` taking `max` on axis `a` when bit `a` is set.
struct Corners {
    x: [f64; 8],
    y: [f64; 8],
    depth: [f32; 8],
}

/// The corners of `b` placed by `clip_from_object` ([`clip_corners`]) and projected for a `w × h`
/// frame; None when one is not finite or reaches the near plane. In eight lanes where the
/// processor has AVX2 (the eight corners transformed and divided at once): the scalar path's
/// operations in its order, so its bits (`eight_lanes_project_as_the_scalar_path_does`).
#[inline]
fn project_corners(clip_from_object: &Mat4, b: &Aabb, w: f64, h: f64) -> Option<Corners> {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Isa::detected().avx2() {
        // SAFETY: the token proves AVX2.
        return unsafe { project_corners_avx2(avx2, clip_from_object, b, w, h) };
    }
    project_corners_scalar(clip_from_object, b, w, h)
}

/// [`project_corners`], one corner at a time.
#[inline]
fn project_corners_scalar(clip_from_object: &Mat4, b: &Aabb, w: f64, h: f64) -> Option<Corners> {
    let c = clip_corners(clip_from_object, b)?;
    let xy = c.map(|v| screen_xy(v, w, h));
    Some(Corners {
        x: xy.map(|p| p.0),
        y: xy.map(|p| p.1),
        depth: c.map(|v| v.z / v.w),
    })
}

/// [`project_corners`] in eight lanes, one a corner: each clip coordinate as glam's
/// `Mat4 * Vec4` forms it (`((x_axis·x + y_axis·y) + z_axis·z) + w_axis·1`), the near-plane
/// and finiteness tests of [`clip_corners`], and [`screen_xy`]'s divisions in f64.
///
/// # Safety
/// The processor must have AVX2 (as the token `avx2` proves).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn project_corners_avx2(avx2: Avx2, m: &Mat4, b: &Aabb, w: f64, h: f64) -> Option<Corners> {
    let l = unsafe { project_lanes(avx2, m, b) }?;
    let [x0, x1, y0, y1] = screen_lanes(avx2, &l, w, h).map(F64x4::to_array);
    let join = |lo: [f64; 4], hi: [f64; 4]| std::array::from_fn(|i| if i < 4 { lo[i] } else { hi[i - 4] });
    Some(Corners {
        x: join(x0, x1),
        y: join(y0, y1),
        depth: (l.cz / l.cw).to_array(),
    })
}

/// [`screen_xy`] of the corners in `l`, in f64 lanes: `[x of corners 0-3, x of 4-7, y of 0-3,
/// y of 4-7]`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn screen_lanes(avx2: Avx2, l: &Lanes, w: f64, h: f64) -> [F64x4; 4] {
    let d = |v: f64| F64x4::splat(avx2, v);
    let sx = |x: F64x4, cw: F64x4| (x / cw * d(0.5) + d(0.5)) * d(w);
    let sy = |y: F64x4, cw: F64x4| (d(0.5) - y / cw * d(0.5)) * d(h);
    let (lo_w, hi_w) = (l.cw.low_f64(), l.cw.high_f64());
    [
        sx(l.cx.low_f64(), lo_w),
        sx(l.cx.high_f64(), hi_w),
        sy(l.cy.low_f64(), lo_w),
        sy(l.cy.high_f64(), hi_w),
    ]
}

/// The span of a box's corners on screen, pixels (`[min x, max x, min y, max y]`), and its
/// nearest corner's depth (before the margin): what Greene's whole-box test and a box's screen
/// rectangle need; None as [`project_corners`].
#[inline]
fn project_span(clip_from_object: &Mat4, b: &Aabb, w: f64, h: f64) -> Option<([f64; 4], f32)> {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Isa::detected().avx2() {
        // SAFETY: the token proves AVX2.
        return unsafe { project_span_avx2(avx2, clip_from_object, b, w, h) };
    }
    project_span_scalar(clip_from_object, b, w, h)
}

/// `[min x, max x, min y, max y]` of projected corners.
#[inline]
fn span_of(x: &[f64; 8], y: &[f64; 8]) -> [f64; 4] {
    let span = |v: &[f64; 8]| {
        v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
    };
    let ((minx, maxx), (miny, maxy)) = (span(x), span(y));
    [minx, maxx, miny, maxy]
}

/// [`project_span`] from [`project_corners_scalar`].
#[inline]
fn project_span_scalar(clip_from_object: &Mat4, b: &Aabb, w: f64, h: f64) -> Option<([f64; 4], f32)> {
    let c = project_corners_scalar(clip_from_object, b, w, h)?;
    Some((span_of(&c.x, &c.y), c.depth.iter().copied().fold(0.0f32, f32::max)))
}

/// [`project_span`] in eight lanes ([`project_corners_avx2`]), reduced in lanes: every corner
/// kept lies in front of the eye (`w > 0`) and is finite, so no lane is NaN, and the lanes'
/// `min`/`max` rule agrees with `f64::min`/`max` but for the sign of a zero, which changes no
/// rectangle or comparison.
///
/// # Safety
/// The processor must have AVX2 (as the token `avx2` proves).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn project_span_avx2(avx2: Avx2, m: &Mat4, b: &Aabb, w: f64, h: f64) -> Option<([f64; 4], f32)> {
    let l = unsafe { project_lanes(avx2, m, b) }?;
    let [x0, x1, y0, y1] = screen_lanes(avx2, &l, w, h);
    let lanes_min = |v: F64x4| v.to_array().into_iter().fold(f64::INFINITY, f64::min);
    let lanes_max = |v: F64x4| v.to_array().into_iter().fold(f64::NEG_INFINITY, f64::max);
    let depth = (l.cz / l.cw).to_array().into_iter().fold(0.0f32, f32::max);
    Some((
        [
            lanes_min(x0.min(x1)),
            lanes_max(x0.max(x1)),
            lanes_min(y0.min(y1)),
            lanes_max(y0.max(y1)),
        ],
        depth,
    ))
}

/// A box's corners in clip space, one a lane ([`project_corners_avx2`]).
#[cfg(target_arch = "x86_64")]
struct Lanes {
    cx: F32x8,
    cy: F32x8,
    cz: F32x8,
    cw: F32x8,
}

/// The clip-space corners of `b` in eight lanes, as glam's `Mat4 * Vec4` forms them
/// (`((x_axis·x + y_axis·y) + z_axis·z) + w_axis·1`); None as [`clip_corners`] (a corner not
/// finite, at the near plane, or not in front of the eye).
///
/// # Safety
/// The processor must have AVX2 (as the token `avx2` proves).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn project_lanes(avx2: Avx2, m: &Mat4, b: &Aabb) -> Option<Lanes> {
    let s = |v: f32| F32x8::splat(avx2, v);
    let pick = |lo: f32, hi: f32, bits: u32| F32x8::select(M32x8::from_bits(avx2, bits), s(hi), s(lo));
    let (x, y, z) = (
        pick(b.min.x, b.max.x, 0xaa),
        pick(b.min.y, b.max.y, 0xcc),
        pick(b.min.z, b.max.z, 0xf0),
    );
    let row = |r: usize| ((s(m.x_axis[r]) * x + s(m.y_axis[r]) * y) + s(m.z_axis[r]) * z) + s(m.w_axis[r]);
    let (cx, cy, cz, cw) = (row(0), row(1), row(2), row(3));
    let inf = s(f32::INFINITY);
    let finite = cx
        .abs()
        .lt(inf)
        .and(cy.abs().lt(inf))
        .and(cz.abs().lt(inf))
        .and(cw.abs().lt(inf));
    let near = (cz * s(1.0 + DEPTH_MARGIN)).gt(cw);
    let ahead = cw.gt(F32x8::zero(avx2));
    (finite.and(ahead).and_not(near).bits() == 0xff).then_some(Lanes { cx, cy, cz, cw })
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

/// The screen rectangle `b` may draw into (the whole frame when it reaches the near plane);
/// None for an empty box or an empty rectangle.
pub(crate) fn screen_rect(clip_from_object: &Mat4, b: &Aabb, width: u32, height: u32) -> Option<PixelRect> {
    if b.is_empty() {
        return None;
    }
    let (w, h) = (width as f64, height as f64);
    let r = match project_span(clip_from_object, b, w, h) {
        None => PixelRect {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        },
        Some(([minx, maxx, miny, maxy], _)) => rect_of_span(minx, maxx, miny, maxy, w, h),
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

    /// `Err(hidden)` for an empty box (hidden) or one holding the eye (not hidden).
    #[inline]
    fn outside(b: &Aabb, eye: Vec3) -> Result<(), bool> {
        if b.is_empty() {
            return Err(true);
        }
        // An eye inside (or on, up to rounding) the box sees it from within.
        let slack = b.size() * 1e-4 + Vec3::splat(1e-6);
        if (eye.cmpge(b.min - slack) & eye.cmple(b.max + slack)).all() {
            return Err(false);
        }
        Ok(())
    }

    /// What [`Occlusion::box_hidden`] settles before any pyramid read: `Err(hidden)` for an
    /// empty box (hidden), one holding the eye or reaching the near plane (not hidden); else
    /// the box's corners projected.
    fn testable(&self, clip_from_object: &Mat4, b: &Aabb, eye: Vec3) -> Result<Corners, bool> {
        Self::outside(b, eye)?;
        let (w, h) = (self.frame.width() as f64, self.frame.height() as f64);
        project_corners(clip_from_object, b, w, h).ok_or(false)
    }

    /// §3.2: true when the box `b` (object space, placed by `clip_from_object`, the eye at `eye`
    /// in object space) is hidden behind what is drawn: every front face of the box is hidden
    /// over its screen box, compared at the face's nearest corner; a box at most
    /// `WHOLE_BOX_PIXELS` wide and tall on screen is tested whole instead, as
    /// [`Occlusion::whole_box_query`] and [`Occlusion::rect_hidden`] do. An empty box is hidden; a box
    /// holding the eye or reaching the near plane is not.
    pub fn box_hidden(&self, clip_from_object: &Mat4, b: &Aabb, eye: Vec3, counts: &mut PyramidCounts) -> bool {
        // Each corner projected once (screen position and depth), shared by the faces it is on.
        let c = match self.testable(clip_from_object, b, eye) {
            Ok(c) => c,
            Err(hidden) => return hidden,
        };
        let (w, h) = (self.frame.width() as f64, self.frame.height() as f64);
        let depth = c.depth;
        // A box small on screen: Greene's whole-box test (one rectangle at the nearest depth of
        // all corners) culls about as much as one test per face, for one pyramid test.
        let [minx, maxx, miny, maxy] = span_of(&c.x, &c.y);
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
                    let (x, y) = (c.x[i], c.y[i]);
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
        Self::outside(b, eye)?;
        let (w, h) = (self.frame.width() as f64, self.frame.height() as f64);
        let ([minx, maxx, miny, maxy], nearest) = project_span(clip_from_object, b, w, h).ok_or(false)?;
        let nearest = nearest * (1.0 + DEPTH_MARGIN);
        if nearest < self.far_depth * (1.0 - DEPTH_MARGIN) {
            return Err(true); // beyond the far plane: draws nothing
        }
        Ok((rect_of_span(minx, maxx, miny, maxy, w, h), nearest))
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

    /// The eight-lane projection gives the scalar path's bits: corner positions and depths,
    /// and the same refusals (a corner at the near plane, one not finite), over views from
    /// inside and outside random boxes, some of them with an infinite or NaN bound; the span
    /// reduced in lanes, the scalar span.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_lanes_project_as_the_scalar_path_does() {
        use rand::{Rng, SeedableRng};
        let Some(avx2) = Isa::detected().avx2() else {
            eprintln!("note: no AVX2 here; nothing to compare");
            return;
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let (mut projected, mut refused, mut not_finite) = (0, 0, 0);
        for k in 0..20_000 {
            let v = |rng: &mut rand_pcg::Pcg64Mcg, r: f32| {
                Vec3::new(
                    rng.random_range(-r..r),
                    rng.random_range(-r..r),
                    rng.random_range(-r..r),
                )
            };
            let eye = v(&mut rng, 50.0);
            let camera = occult_core::Camera::look_at(eye, eye + v(&mut rng, 1.0) + Vec3::new(0.0, 0.0, 1e-3));
            let view = occult_core::View::new(camera, 640, 360).expect("a view");
            let placed = Mat4::from_scale_rotation_translation(
                Vec3::splat(rng.random_range(0.1..3.0)),
                occult_core::glam::Quat::from_rotation_y(rng.random_range(0.0..6.3)),
                v(&mut rng, 20.0),
            );
            let m = view.clip_from_world() * placed;
            let c = v(&mut rng, 30.0);
            let mut b = Aabb::new(c, c + v(&mut rng, 10.0).abs());
            match k % 499 {
                0 => b.max.x = f32::INFINITY,
                1 => b.min.y = f32::NEG_INFINITY,
                2 => b.max.z = f32::NAN,
                _ => {}
            }
            let (w, h) = (640.0, 360.0);
            let scalar = project_corners_scalar(&m, &b, w, h);
            // SAFETY: the token proves AVX2.
            let lanes = unsafe { project_corners_avx2(avx2, &m, &b, w, h) };
            match (scalar, lanes) {
                (None, None) => refused += 1,
                (Some(a), Some(l)) => {
                    projected += 1;
                    assert_eq!(a.x.map(f64::to_bits), l.x.map(f64::to_bits), "box {k}");
                    assert_eq!(a.y.map(f64::to_bits), l.y.map(f64::to_bits), "box {k}");
                    assert_eq!(a.depth.map(f32::to_bits), l.depth.map(f32::to_bits), "box {k}");
                }
                (a, l) => panic!("box {k}: scalar {:?}, lanes {:?}", a.is_some(), l.is_some()),
            }
            if k % 499 < 3 {
                not_finite += 1;
                assert!(lanes_refused(avx2, &m, &b), "box {k}: a bound not finite is refused");
            }
            // The span reduced in lanes: the same values (a zero's sign aside).
            // SAFETY: the token proves AVX2.
            let span = unsafe { project_span_avx2(avx2, &m, &b, w, h) };
            assert_eq!(span, project_span_scalar(&m, &b, w, h), "box {k}");
        }
        assert!(
            projected > 1000 && refused > 1000 && not_finite > 100,
            "{projected} projected, {refused} refused, {not_finite} not finite"
        );
    }

    /// Whether the lanes refuse `b` (tests).
    #[cfg(target_arch = "x86_64")]
    fn lanes_refused(avx2: Avx2, m: &Mat4, b: &Aabb) -> bool {
        // SAFETY: the token proves AVX2.
        unsafe { project_lanes(avx2, m, b) }.is_none()
    }

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
