//! Depth queries against a frame's current depth: the software stand-in for occlusion queries.
//!
//! Both queries are conservative with respect to the rasterizer: if any triangle inside the
//! queried volume would write a fragment now, the count is non-zero. They are never exact in
//! the other direction (a box may report samples although its contents are hidden).

use crate::frame::Frame;
use occult_core::{Aabb, Mat4, View};

/// An inclusive-exclusive pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl PixelRect {
    /// The whole of `frame`.
    pub fn whole(frame: &Frame) -> Self {
        Self {
            x0: 0,
            y0: 0,
            x1: frame.width(),
            y1: frame.height(),
        }
    }

    /// Pixels in the rectangle (0 when empty).
    pub fn area(&self) -> u64 {
        self.x1.saturating_sub(self.x0) as u64 * self.y1.saturating_sub(self.y0) as u64
    }

    /// The pixels in both rectangles; `None` when there are none.
    pub fn intersect(&self, other: &PixelRect) -> Option<PixelRect> {
        let r = PixelRect {
            x0: self.x0.max(other.x0),
            y0: self.y0.max(other.y0),
            x1: self.x1.min(other.x1),
            y1: self.y1.min(other.y1),
        };
        (r.x0 < r.x1 && r.y0 < r.y1).then_some(r)
    }
}

/// Counts the pixels of `rect` (clipped to the frame) where a fragment at depth `nearest`
/// could still be kept: those whose stored depth is not nearer than `nearest` (ties count, as
/// a tie can be won by a smaller item id). A NaN `nearest` counts every pixel.
pub fn query_rect(frame: &Frame, rect: PixelRect, nearest: f32) -> u64 {
    let x1 = rect.x1.min(frame.width());
    let y1 = rect.y1.min(frame.height());
    if rect.x0 >= x1 || rect.y0 >= y1 {
        return 0;
    }
    let nearest = if nearest.is_nan() { f32::INFINITY } else { nearest };
    let w = frame.width() as usize;
    let mut count = 0;
    for y in rect.y0..y1 {
        let row = &frame.depth()[y as usize * w + rect.x0 as usize..y as usize * w + x1 as usize];
        count += row.iter().filter(|&&d| d <= nearest).count() as u64;
    }
    count
}

/// The occlusion query of a box: counts the pixels inside the box's projected silhouette (the
/// convex hull of its projected corners, widened by 1/64 pixel) whose stored depth is not
/// nearer than the box's nearest corner. Returns 0 for a box wholly outside the view or beyond
/// the far plane; a box that reaches the near plane counts every pixel of the frame it could
/// touch (it may cover anything). `clip_from_object` places the box, as in [`crate::Draw`].
pub fn query_box(frame: &Frame, view: &View, clip_from_object: &Mat4, aabb: &Aabb) -> u64 {
    query_box_counted(frame, view, clip_from_object, aabb).samples
}

/// What [`query_box_counted`] found and what it cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BoxQuery {
    /// The samples that pass (the result of [`query_box`]).
    pub samples: u64,
    /// The depth comparisons made: every pixel centre inside the silhouette (a hardware
    /// occlusion query with back-face culling compares each once), the whole frame for a box
    /// reaching the near plane, 0 for one rejected before any pixel.
    pub comparisons: u64,
}

/// [`query_box`] with its cost: the samples and the depth comparisons made.
pub fn query_box_counted(frame: &Frame, view: &View, clip_from_object: &Mat4, aabb: &Aabb) -> BoxQuery {
    let none = BoxQuery::default();
    if aabb.is_empty() {
        return none;
    }
    let (w, h) = (frame.width() as f64, frame.height() as f64);
    let clip = aabb.corners().map(|c| *clip_from_object * c.extend(1.0));
    // A box that may cover anything: every pixel where anything could still be drawn.
    let everywhere = || BoxQuery {
        samples: query_rect(frame, PixelRect::whole(frame), f32::INFINITY),
        comparisons: PixelRect::whole(frame).area(),
    };
    if clip.iter().any(|c| !c.is_finite()) {
        return everywhere();
    }
    // Outside one side plane entirely (with a margin for snapping): nothing can be drawn.
    let m = 1.0 + 4.0 / w.min(h) as f32;
    let outside = |f: &dyn Fn(&occult_core::Vec4) -> bool| clip.iter().all(f);
    if outside(&|c| c.x < -c.w * m)
        || outside(&|c| c.x > c.w * m)
        || outside(&|c| c.y < -c.w * m)
        || outside(&|c| c.y > c.w * m)
    {
        return none;
    }
    let near_margin = 1.0 + 1e-5;
    if clip.iter().any(|c| c.z * near_margin > c.w) {
        return everywhere();
    }
    let nearest = clip.iter().map(|c| c.z / c.w).fold(0.0f32, f32::max) * (1.0 + 1e-5);
    if nearest < view.far_depth() * (1.0 - 1e-5) {
        return none;
    }
    let pts: Vec<(f64, f64)> = clip
        .iter()
        .map(|c| {
            let (x, y, cw) = (c.x as f64, c.y as f64, c.w as f64);
            ((x / cw * 0.5 + 0.5) * w, (0.5 - y / cw * 0.5) * h)
        })
        .collect();
    let hull = convex_hull(pts);
    let margin = 1.0 / 64.0;
    let (mut minx, mut maxx, mut miny, mut maxy) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in &hull {
        minx = minx.min(x);
        maxx = maxx.max(x);
        miny = miny.min(y);
        maxy = maxy.max(y);
    }
    let px0 = ((minx - margin - 0.5).ceil().max(0.0)) as u32;
    let py0 = ((miny - margin - 0.5).ceil().max(0.0)) as u32;
    let px1 = ((maxx + margin - 0.5).floor().min(w - 1.0)).max(-1.0) as i64 + 1;
    let py1 = ((maxy + margin - 0.5).floor().min(h - 1.0)).max(-1.0) as i64 + 1;
    if px1 <= px0 as i64 || py1 <= py0 as i64 {
        return none;
    }
    // Edges of the counter-clockwise (y down: clockwise on screen) hull as half-planes with the
    // interior on the non-negative side, each widened by `margin`.
    let n = hull.len();
    let edges: Vec<(f64, f64, f64)> = if n < 3 {
        Vec::new() // degenerate hull (a box seen edge-on): the bounding rectangle decides
    } else {
        (0..n)
            .map(|i| {
                let (ax, ay) = hull[i];
                let (bx, by) = hull[(i + 1) % n];
                let (nx, ny) = (ay - by, bx - ax);
                let len = (nx * nx + ny * ny).sqrt().max(1e-300);
                (nx / len, ny / len, -(nx * ax + ny * ay) / len + margin)
            })
            .collect()
    };
    let fw = frame.width() as usize;
    let mut q = none;
    for y in py0..py1 as u32 {
        let cy = y as f64 + 0.5;
        for x in px0..px1 as u32 {
            let cx = x as f64 + 0.5;
            if edges.iter().all(|&(a, b, c)| a * cx + b * cy + c >= 0.0) {
                q.comparisons += 1;
                q.samples += u64::from(frame.depth()[y as usize * fw + x as usize] <= nearest);
            }
        }
    }
    q
}

/// Convex hull (Andrew's monotone chain), in the orientation where `(ay - by, bx - ax)` points
/// inwards for consecutive hull points a, b.
fn convex_hull(mut p: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    p.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0);
    let mut hull: Vec<(f64, f64)> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_orientation_puts_interior_on_positive_side() {
        let h = convex_hull(vec![(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0), (2.0, 2.0)]);
        assert_eq!(h.len(), 4);
        for i in 0..h.len() {
            let (a, b) = (h[i], h[(i + 1) % h.len()]);
            let (nx, ny) = (a.1 - b.1, b.0 - a.0);
            assert!(nx * (2.0 - a.0) + ny * (2.0 - a.1) > 0.0);
        }
    }

    #[test]
    fn rect_query_edge_cases() {
        let f = Frame::new(8, 8).expect("an 8x8 frame");
        let rect = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        // (rectangle, depth, samples): whole frame, empty, clipped, outside, NaN depth.
        for (r, depth, want) in [
            (rect(0, 0, 8, 8), 0.5, 64),
            (rect(5, 5, 2, 2), 0.5, 0),
            (rect(6, 6, 100, 100), 0.5, 4),
            (rect(100, 100, 200, 200), 0.5, 0),
            (rect(0, 0, 8, 8), f32::NAN, 64),
        ] {
            assert_eq!(query_rect(&f, r, depth), want, "{r:?} at {depth}");
        }
    }
}
