//! The occlusion query of a cell: "would any fragment of this box pass the depth test now?"
//!
//! The same test as [`occult_raster::query_box`] (projected convex hull of the box's corners,
//! widened by 1/64 pixel, against the box's nearest corner depth with the same margins), with
//! two changes that make it cheap, which matters because the number of queries a frame can
//! afford decides how much the algorithm culls (§3.4):
//! - it answers *any sample passed* (the `GL_ANY_SAMPLES_PASSED` form of a hardware query)
//!   and stops at the first passing pixel instead of counting them all;
//! - it scans each row of the hull as one span (its ends from the hull's edges, widened by a
//!   hair so the span holds every pixel `query_box` would test) with a branch-free compare over
//!   the depth row, instead of testing every edge at every pixel.
//!
//! It is never `false` where `query_box` counts a sample (tested on random boxes), so it is as
//! conservative as `query_box`.
//!
//! [`query_cell`] may first ask a max-depth pyramid of the current depth
//! ([`occult_raster::ZPyramid`]) about the silhouette's bounding rectangle, against the same
//! nearest depth: when every pixel of the rectangle is nearer, no pixel of the silhouette (which
//! lies inside it) can pass, and the span scan is skipped. A stale pyramid only answers "don't
//! know", so the cheap test is as conservative as the scan; the scan runs where it is
//! inconclusive.

use occult_core::{Aabb, Mat4, Vec4, View};
use occult_raster::{Frame, PixelRect, PyramidCounts, PyramidTest, ZPyramid};

/// What a cell's query found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QueryOutcome {
    /// Some pixel of the silhouette may pass: the cell's contents must be drawn.
    Visible,
    /// Hidden, answered by the pyramid (the cheap test) alone.
    HiddenByPyramid,
    /// Hidden, answered by the span scan (or empty, off screen, beyond the far plane).
    Hidden,
}

/// True when some pixel inside the box's projected silhouette has a stored depth not nearer
/// than the box's nearest point (a fragment of the box could pass); see the module doc. Only
/// the pixels of the view's region count ([`View::with_region`]: a frame drawn in strips or
/// bands holds the blocked depth beside its region, which no box passes).
pub fn any_sample_passes(frame: &Frame, view: &View, clip_from_object: &Mat4, aabb: &Aabb) -> bool {
    query_cell(frame, view, clip_from_object, aabb, None) == QueryOutcome::Visible
}

/// The query of [`any_sample_passes`], asking `pyramid` (a max-depth pyramid of `frame`, possibly
/// stale) first about the silhouette's bounding rectangle; the span scan runs only where the
/// pyramid does not find the rectangle hidden. Visible exactly where [`any_sample_passes`] is
/// true.
///
/// # Panics
/// If `pyramid` is not of `frame`'s size (a programmer error).
pub fn query_cell(
    frame: &Frame,
    view: &View,
    clip_from_object: &Mat4,
    aabb: &Aabb,
    pyramid: Option<&ZPyramid>,
) -> QueryOutcome {
    use QueryOutcome::{Hidden, HiddenByPyramid, Visible};
    if aabb.is_empty() {
        return Hidden;
    }
    let (w, h) = (frame.width() as f64, frame.height() as f64);
    let clip: [Vec4; 8] = aabb.corners().map(|c| *clip_from_object * c.extend(1.0));
    // A box that may cover anything passes (every stored depth is finite).
    if clip.iter().any(|c| !c.is_finite()) {
        return Visible;
    }
    let m = 1.0 + 4.0 / w.min(h) as f32;
    if clip.iter().all(|c| c.x < -c.w * m)
        || clip.iter().all(|c| c.x > c.w * m)
        || clip.iter().all(|c| c.y < -c.w * m)
        || clip.iter().all(|c| c.y > c.w * m)
    {
        return Hidden;
    }
    let near_margin = 1.0 + 1e-5;
    if clip.iter().any(|c| c.z * near_margin > c.w) {
        return Visible;
    }
    let nearest = clip.iter().map(|c| c.z / c.w).fold(0.0f32, f32::max) * (1.0 + 1e-5);
    if nearest < view.far_depth() * (1.0 - 1e-5) {
        return Hidden;
    }
    let mut pts = [(0.0f64, 0.0f64); 8];
    for (p, c) in pts.iter_mut().zip(&clip) {
        let (x, y, cw) = (c.x as f64, c.y as f64, c.w as f64);
        *p = ((x / cw * 0.5 + 0.5) * w, (0.5 - y / cw * 0.5) * h);
    }
    // The hull's bounding box is the corners' (its vertices are corners, the extreme ones among
    // them), so the rectangle is known before the hull is.
    let (px0, py0, px1, py1) = pixel_bounds(&pts, w, h);
    // The view's region only: beside it a frame drawn in parts is blocked.
    let (c, r) = (view.columns(), view.rows());
    let (px0, px1) = (px0.max(i64::from(c.start)), px1.min(i64::from(c.end)));
    let (py0, py1) = (py0.max(i64::from(r.start)), py1.min(i64::from(r.end)));
    if px1 <= px0 || py1 <= py0 {
        return Hidden;
    }
    if let Some(pyramid) = pyramid {
        let rect = PixelRect {
            x0: px0 as u32,
            y0: py0 as u32,
            x1: px1 as u32,
            y1: py1 as u32,
        };
        let how = PyramidTest {
            global: true,
            hierarchical: true,
        };
        if pyramid.occludes(frame, rect, nearest, how, &mut PyramidCounts::default()) {
            return HiddenByPyramid;
        }
    }
    let mut hull = [(0.0f64, 0.0f64); 16];
    let n = convex_hull(&mut pts, &mut hull);
    let hull = &hull[..n];
    let margin = SNAP_MARGIN;
    // Edge half-planes a·x + b·y + c ≥ 0 (interior side), widened by `margin`, as query_box.
    let mut edges = [(0.0f64, 0.0f64, 0.0f64); 16];
    let edge_count = if n < 3 { 0 } else { n };
    for i in 0..edge_count {
        let (ax, ay) = hull[i];
        let (bx, by) = hull[(i + 1) % n];
        let (nx, ny) = (ay - by, bx - ax);
        let len = (nx * nx + ny * ny).sqrt().max(1e-300);
        edges[i] = (nx / len, ny / len, -(nx * ax + ny * ay) / len + margin);
    }
    let edges = &edges[..edge_count];
    // Widening of each span end, in pixels: covers the rounding of the division below.
    const SPAN_SLACK: f64 = 1e-6;
    let fw = frame.width() as usize;
    let depth = frame.depth();
    for y in py0..py1 {
        let cy = y as f64 + 0.5;
        let (mut lo, mut hi) = (px0 as f64, (px1 - 1) as f64);
        for &(a, b, c) in edges {
            let t = -(b * cy + c);
            if a > 0.0 {
                lo = lo.max((t / a - 0.5 - SPAN_SLACK).ceil());
            } else if a < 0.0 {
                hi = hi.min((t / a - 0.5 + SPAN_SLACK).floor());
            } else if t > 0.0 {
                lo = f64::INFINITY; // b·cy + c < 0: the row is outside this edge
            }
        }
        if lo > hi {
            continue;
        }
        let row = &depth[y as usize * fw..y as usize * fw + fw];
        if span_has_far_sample(&row[lo as usize..=hi as usize], nearest) {
            return Visible;
        }
    }
    Hidden
}

/// Pixel margin for vertex snapping, as [`occult_raster::query_box`].
const SNAP_MARGIN: f64 = 1.0 / 64.0;

/// The pixels `[x0, x1) × [y0, y1)` whose centres lie within [`SNAP_MARGIN`] of the bounding
/// box of screen points `pts` (pixels, y down), clipped to the `w × h` frame (possibly empty).
fn pixel_bounds(pts: &[(f64, f64)], w: f64, h: f64) -> (i64, i64, i64, i64) {
    let (mut minx, mut maxx, mut miny, mut maxy) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in pts {
        minx = minx.min(x);
        maxx = maxx.max(x);
        miny = miny.min(y);
        maxy = maxy.max(y);
    }
    let px0 = ((minx - SNAP_MARGIN - 0.5).ceil().max(0.0)) as i64;
    let py0 = ((miny - SNAP_MARGIN - 0.5).ceil().max(0.0)) as i64;
    let px1 = ((maxx + SNAP_MARGIN - 0.5).floor().min(w - 1.0)).max(-1.0) as i64 + 1;
    let py1 = ((maxy + SNAP_MARGIN - 0.5).floor().min(h - 1.0)).max(-1.0) as i64 + 1;
    (px0, py0, px1, py1)
}

// The pixels a box may draw into (the region a pyramid update must cover after the box's
// contents are drawn): `hzb`'s, with the same margins, its corners projected in lanes.
pub(super) use crate::hzb::boxtest::screen_rect;

/// True when some depth in `span` is not nearer than `nearest`; compares 16 at a time without
/// branches so the loop vectorizes.
#[inline]
fn span_has_far_sample(span: &[f32], nearest: f32) -> bool {
    let mut chunks = span.chunks_exact(16);
    for c in &mut chunks {
        let mut any = false;
        for &d in c {
            any |= d <= nearest;
        }
        if any {
            return true;
        }
    }
    chunks.remainder().iter().any(|&d| d <= nearest)
}

/// Convex hull (Andrew's monotone chain) of `p` into `out`, in the orientation of
/// `occult_raster::query_box` (`(ay - by, bx - ax)` points inwards); returns its length.
fn convex_hull(p: &mut [(f64, f64); 8], out: &mut [(f64, f64); 16]) -> usize {
    p.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let mut uniq = [(0.0, 0.0); 8];
    let mut m = 0;
    for &q in p.iter() {
        if m == 0 || uniq[m - 1] != q {
            uniq[m] = q;
            m += 1;
        }
    }
    if m < 3 {
        out[..m].copy_from_slice(&uniq[..m]);
        return m;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0);
    let mut k = 0;
    for pass in 0..2 {
        let start = k;
        for j in 0..m {
            let q = if pass == 0 { uniq[j] } else { uniq[m - 1 - j] };
            while k >= start + 2 && cross(out[k - 2], out[k - 1], q) <= 0.0 {
                k -= 1;
            }
            out[k] = q;
            k += 1;
        }
        k -= 1;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{Affine3A, Camera, Mesh, Vec3};
    use occult_raster::{query_box, Draw, DrawTriangles, RasterConfig, RasterMode, Rasterizer};

    /// A small deterministic generator (xorshift), uniform in `lo..hi`.
    struct Rng(u64);
    impl Rng {
        fn random_range(&mut self, r: std::ops::Range<f32>) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            r.start + (r.end - r.start) * ((self.0 >> 40) as f32 / (1u64 << 24) as f32)
        }
    }

    /// A view restricted to a region ([`View::with_region`]) is asked about its region's
    /// pixels only: a box whose far pixels lie beside the region is hidden to it, visible to
    /// the whole view; one with far pixels inside it is visible to both, pyramid or not.
    #[test]
    fn a_region_is_asked_about_its_pixels_only() {
        let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO), 64, 32).expect("a 64x32 view");
        let clip = view.clip_from_object(&Affine3A::IDENTITY);
        let left = view.with_region(0..32, 0..32).expect("the left half");
        let right = view.with_region(32..64, 0..32).expect("the right half");
        // Near depth on the left half, far (cleared, 0 in reversed z) on the right.
        let mut frame = Frame::new(64, 32).expect("a 64x32 frame");
        let near = 0.5f32; // reversed z: at a fifth of a unit from the eye
        {
            let (depth, _) = frame.buffers_mut();
            for row in depth.chunks_mut(64) {
                row[..32].fill(near);
            }
        }
        let mut pyramid = ZPyramid::new(64, 32).expect("a pyramid");
        pyramid.rebuild(&frame);
        // A box across the middle, well behind the near depth.
        let b = Aabb::new(Vec3::new(-1.0, -0.5, -1.0), Vec3::new(1.0, 0.5, 0.0));
        for p in [None, Some(&pyramid)] {
            assert_eq!(query_cell(&frame, &view, &clip, &b, p), QueryOutcome::Visible);
            assert_eq!(query_cell(&frame, &right, &clip, &b, p), QueryOutcome::Visible);
            assert_ne!(query_cell(&frame, &left, &clip, &b, p), QueryOutcome::Visible);
        }
    }

    /// Wherever `query_box` counts a sample, the early-out query passes too; and it agrees
    /// with it almost everywhere (it may only pass more, by its hair-wide span slack).
    #[test]
    fn never_stricter_than_query_box() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut p = Vec::new();
        let mut t = Vec::new();
        for i in 0..200u32 {
            let c = Vec3::new(
                rng.random_range(-4.0..4.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-4.0..4.0),
            );
            for _ in 0..3 {
                p.push(
                    c + Vec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    ),
                );
            }
            t.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let mesh = Mesh::new(p, t).expect("a soup of in-range triangles is a valid mesh");
        let mut raster = Rasterizer::new(RasterConfig::default()).expect("the default raster config is valid");
        let mut disagreements = 0;
        let mut total = 0;
        for v in 0..8 {
            let eye = Vec3::new(rng.random_range(-9.0..9.0), rng.random_range(-3.0..3.0), 9.0 + v as f32);
            let view = View::new(Camera::look_at(eye, Vec3::ZERO), 96, 64).expect("a 96x64 view of the soup");
            let mut frame = Frame::new(96, 64).expect("a 96x64 frame");
            let clip = view.clip_from_object(&Affine3A::IDENTITY);
            let draw = Draw {
                mesh: &mesh,
                triangles: DrawTriangles::All,
                clip_from_object: clip,
                first_item: 0,
            };
            raster.draw(&view, &mut frame, &[draw], RasterMode::Full);
            for _ in 0..500 {
                let c = Vec3::new(
                    rng.random_range(-12.0..12.0),
                    rng.random_range(-6.0..6.0),
                    rng.random_range(-12.0..12.0),
                );
                let e = Vec3::new(
                    rng.random_range(0.0..2.0),
                    rng.random_range(0.0..2.0),
                    rng.random_range(0.0..2.0),
                );
                let b = Aabb::new(c - e, c + e);
                let count = query_box(&frame, &view, &clip, &b);
                let any = any_sample_passes(&frame, &view, &clip, &b);
                assert!(
                    count == 0 || any,
                    "box {b:?} has {count} samples but the query says none"
                );
                total += 1;
                disagreements += (any != (count > 0)) as u32;
            }
        }
        assert!(disagreements * 100 < total, "{disagreements} of {total} differ");
    }

    /// With a pyramid of the frame (fresh, or stale: built before the last draw), the query
    /// answers exactly as without one, and the pyramid alone answers some hidden boxes.
    #[test]
    fn pyramid_changes_no_answer() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        // A wall of two triangles at z = 0 in front of the boxes, half the screen wide.
        let wall = Mesh::new(
            vec![
                Vec3::new(-6.0, -6.0, 0.0),
                Vec3::new(0.5, -6.0, 0.0),
                Vec3::new(0.5, 6.0, 0.0),
                Vec3::new(-6.0, 6.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .expect("two in-range triangles are a valid mesh");
        let small = Mesh::new(
            vec![
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(3.0, 0.0, 1.0),
                Vec3::new(2.0, 2.0, 1.0),
            ],
            vec![[0, 1, 2]],
        )
        .expect("one in-range triangle is a valid mesh");
        let view =
            View::new(Camera::look_at(Vec3::new(0.0, 0.0, 8.0), Vec3::ZERO), 96, 64).expect("a 96x64 view of the wall");
        let clip = view.clip_from_object(&Affine3A::IDENTITY);
        let mut raster = Rasterizer::new(RasterConfig::default()).expect("the default raster config is valid");
        let mut frame = Frame::new(96, 64).expect("a 96x64 frame");
        fn draw(mesh: &Mesh, clip_from_object: Mat4) -> Draw<'_> {
            Draw {
                mesh,
                triangles: DrawTriangles::All,
                clip_from_object,
                first_item: 0,
            }
        }
        raster.draw(&view, &mut frame, &[draw(&wall, clip)], RasterMode::Full);
        let mut stale = ZPyramid::new(96, 64).expect("a 96x64 pyramid");
        stale.rebuild(&frame);
        raster.draw(&view, &mut frame, &[draw(&small, clip)], RasterMode::Full);
        let mut fresh = ZPyramid::new(96, 64).expect("a 96x64 pyramid");
        fresh.rebuild(&frame);
        let mut by_pyramid = 0;
        for _ in 0..2000 {
            let c = Vec3::new(
                rng.random_range(-5.0..5.0),
                rng.random_range(-4.0..4.0),
                rng.random_range(-6.0..3.0),
            );
            let e = Vec3::new(
                rng.random_range(0.0..1.5),
                rng.random_range(0.0..1.5),
                rng.random_range(0.0..1.5),
            );
            let b = Aabb::new(c - e, c + e);
            let exact = any_sample_passes(&frame, &view, &clip, &b);
            for pyramid in [&fresh, &stale] {
                let o = query_cell(&frame, &view, &clip, &b, Some(pyramid));
                assert_eq!(o == QueryOutcome::Visible, exact, "box {b:?}");
                by_pyramid += (o == QueryOutcome::HiddenByPyramid) as u32;
            }
        }
        assert!(by_pyramid > 0, "the pyramid answered no query");
    }

    /// The screen rectangle holds every pixel the box's query scans; the whole frame when the
    /// box reaches the near plane; nothing for an empty or off-screen box.
    #[test]
    fn screen_rect_bounds_the_box() {
        let view = View::new(Camera::look_at(Vec3::new(0.3, 0.2, 5.0), Vec3::ZERO), 64, 48)
            .expect("a 64x48 view of the boxes");
        let clip = view.clip_from_object(&Affine3A::IDENTITY);
        let frame = Frame::new(64, 48).expect("a 64x48 frame");
        for b in [
            Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)),
            Aabb::new(Vec3::new(2.0, 1.0, -3.0), Vec3::new(2.5, 1.2, -2.0)),
        ] {
            let r = screen_rect(&clip, &b, 64, 48).expect("a box in view has a screen rectangle");
            assert!(query_box(&frame, &view, &clip, &b) <= r.area());
            assert!(r.x1 <= 64 && r.y1 <= 48 && r.x0 < r.x1 && r.y0 < r.y1);
        }
        let near = Aabb::new(Vec3::new(0.0, 0.0, 4.95), Vec3::new(1.0, 1.0, 6.0));
        assert_eq!(
            screen_rect(&clip, &near, 64, 48)
                .expect("a box through the near plane covers the screen")
                .area(),
            64 * 48
        );
        let nan = Aabb::new(Vec3::splat(f32::NAN), Vec3::splat(1.0));
        assert!(screen_rect(&clip, &nan, 64, 48).is_none_or(|r| r.area() == 64 * 48));
        assert!(screen_rect(&clip, &Aabb::EMPTY, 64, 48).is_none());
        let aside = Aabb::new(Vec3::new(30.0, 0.0, -10.0), Vec3::new(31.0, 1.0, -9.0));
        assert!(screen_rect(&clip, &aside, 64, 48).is_none());
    }

    #[test]
    fn empty_and_behind_boxes() {
        let view = occult_core::View::new(Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO), 32, 32)
            .expect("a 32x32 view");
        let frame = Frame::new(32, 32).expect("a 32x32 frame");
        let clip = view.clip_from_object(&Affine3A::IDENTITY);
        assert!(!any_sample_passes(&frame, &view, &clip, &Aabb::EMPTY));
        // Behind the camera.
        let behind = Aabb::new(Vec3::new(-1.0, -1.0, 8.0), Vec3::new(1.0, 1.0, 9.0));
        assert!(!any_sample_passes(&frame, &view, &clip, &behind));
        // Around the eye: may cover anything.
        let around = Aabb::new(Vec3::splat(-10.0), Vec3::splat(10.0));
        assert!(any_sample_passes(&frame, &view, &clip, &around));
        // In front, on a cleared frame.
        let front = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
        assert!(any_sample_passes(&frame, &view, &clip, &front));
        // NaN corners pass (conservative).
        let nan = Aabb::new(Vec3::splat(f32::NAN), Vec3::splat(1.0));
        let _ = any_sample_passes(&frame, &view, &clip, &nan);
    }
}
