//! Object-oriented ray casting (§III.C): the screen polygon of a projected box, and the
//! done-mask of pixels that get a ray.

use occult_core::{Aabb, ItemId, Mat4, Vec2, Vec3, Vec4};
use rayon::prelude::*;

use super::cast::InstanceRec;
use super::Accel;

/// Margin by which a polygon is grown, in pixels: the rasterizer snaps vertices to 1/256 pixel,
/// and a triangle inside the box covers only pixel centres within that of the box's projection.
const GROW_PX: f64 = 0.5;

/// The screen projection of a box: a convex polygon of 4, 5 or 6 sides (the hull of the
/// projected corners, [`Hull::of`]), or the whole screen when a corner lies near or behind the
/// eye.
pub(super) enum Projection {
    /// The projected corners and their bounding pixel rectangle `[x0, x1] × [y0, y1]`
    /// (inclusive, clamped to the screen). The hull is left to the caller: most boxes of a far
    /// set fall on pixels already marked, which the rectangle tells without it.
    Polygon { corners: [Vec2; 8], rect: [u32; 4] },
    /// Covers everything.
    Screen,
    /// Off screen.
    Nothing,
}

/// Projects `b` (object space) with `clip_from_object` onto a `width × height` screen.
/// §III.C: the base corner is projected once and the other corners by adding the projected
/// edge offset vectors (clip space is linear in the corner).
pub(super) fn project_box(clip_from_object: &Mat4, b: &Aabb, width: u32, height: u32, near: f32) -> Projection {
    let base = *clip_from_object * b.min.extend(1.0);
    let s = b.size();
    let ex = clip_from_object.x_axis * s.x;
    let ey = clip_from_object.y_axis * s.y;
    let ez = clip_from_object.z_axis * s.z;
    let mut pts = [Vec2::ZERO; 8];
    for (i, p) in pts.iter_mut().enumerate() {
        let mut c: Vec4 = base;
        if i & 1 != 0 {
            c += ex;
        }
        if i & 2 != 0 {
            c += ey;
        }
        if i & 4 != 0 {
            c += ez;
        }
        // A corner near or behind the eye: the projection is unbounded.
        if !c.is_finite() || c.w <= near * 0.5 {
            return Projection::Screen;
        }
        *p = Vec2::new(
            (c.x / c.w * 0.5 + 0.5) * width as f32,
            (0.5 - c.y / c.w * 0.5) * height as f32,
        );
    }
    let lo = pts.iter().fold(Vec2::splat(f32::INFINITY), |a, &p| a.min(p)) - GROW_PX as f32;
    let hi = pts.iter().fold(Vec2::splat(f32::NEG_INFINITY), |a, &p| a.max(p)) + GROW_PX as f32;
    // Pixel centres x + 0.5 in [lo, hi].
    let x0 = (lo.x - 0.5).ceil().max(0.0);
    let y0 = (lo.y - 0.5).ceil().max(0.0);
    let x1 = (hi.x - 0.5).floor().min(width as f32 - 1.0);
    let y1 = (hi.y - 0.5).floor().min(height as f32 - 1.0);
    if x0 > x1 || y0 > y1 {
        return Projection::Nothing;
    }
    Projection::Polygon {
        corners: pts,
        rect: [x0 as u32, x1 as u32, y0 as u32, y1 as u32],
    }
}

/// The convex hull of a box's projected corners, counter-clockwise (in y-down screen space,
/// clockwise visually), held in place (no allocation: a far set has hundreds of thousands of
/// boxes), with each edge's length for the distance test (the same arithmetic as a hull of
/// any length: the mask does not depend on how it is held).
pub(super) struct Hull {
    /// Room for every point the chains may keep: 8 in exact arithmetic, more where rounded
    /// orientation tests disagree on nearly collinear corners (none is dropped).
    pts: [Vec2; HULL_ROOM],
    /// Per edge `i` (from point `i` to the next): its length.
    len_of: [f64; HULL_ROOM],
    len: usize,
}

/// Points a [`Hull`] holds at most: both chains of 8 corners, less their shared ends.
const HULL_ROOM: usize = 16;

impl Hull {
    /// Andrew's monotone chain over the corners; collinear points dropped.
    pub(super) fn of(mut corners: [Vec2; 8]) -> Self {
        corners.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
        let cross = |o: Vec2, a: Vec2, b: Vec2| {
            (a.x - o.x) as f64 * (b.y - o.y) as f64 - (a.y - o.y) as f64 * (b.x - o.x) as f64
        };
        // The lower chain keeps at most 8 points, the upper at most 8 more before each drops
        // its last: at most 16.
        let mut hull = [Vec2::ZERO; HULL_ROOM + 1];
        let mut n = 0;
        for pass in 0..2 {
            let start = n;
            for k in 0..8 {
                let p = if pass == 0 { corners[k] } else { corners[7 - k] };
                while n >= start + 2 && cross(hull[n - 2], hull[n - 1], p) <= 0.0 {
                    n -= 1;
                }
                hull[n] = p;
                n += 1;
            }
            n -= 1;
        }
        let mut out = Self {
            pts: [Vec2::ZERO; HULL_ROOM],
            len_of: [0.0; HULL_ROOM],
            len: n,
        };
        out.pts[..n].copy_from_slice(&hull[..n]);
        for i in 0..n {
            let (a, b) = (out.pts[i], out.pts[(i + 1) % n]);
            out.len_of[i] = ((b - a).length() as f64).max(1e-30);
        }
        out
    }

    /// The hull's points.
    #[cfg(test)]
    pub(super) fn points(&self) -> &[Vec2] {
        &self.pts[..self.len]
    }

    /// True when the point is inside the hull grown by [`GROW_PX`]. A degenerate hull (fewer
    /// than 3 points: a box seen edge-on) holds the points within the margin of its segment.
    pub(super) fn inside(&self, x: f32, y: f32) -> bool {
        let (hull, n) = (&self.pts, self.len);
        if n < 3 {
            return match n {
                0 => false,
                1 => (hull[0] - Vec2::new(x, y)).length() as f64 <= GROW_PX,
                _ => segment_distance(hull[0], hull[1], Vec2::new(x, y)) <= GROW_PX,
            };
        }
        (0..n).all(|i| {
            let a = hull[i];
            let b = hull[(i + 1) % n];
            let e = (b.x - a.x) as f64 * (y - a.y) as f64 - (b.y - a.y) as f64 * (x - a.x) as f64;
            // The hull runs counter-clockwise in (x, y) coordinates: inside is e >= 0.
            e / self.len_of[i] >= -GROW_PX
        })
    }
}

fn segment_distance(a: Vec2, b: Vec2, p: Vec2) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-30)).clamp(0.0, 1.0);
    (a + ab * t - p).length() as f64
}

/// Largest screen rectangle, in pixels per far leaf of the instance, of an instance's box that
/// the object-oriented ray casting's mask scans before projecting the instance's far leaves
/// one by one (§III.C): a scan costs about a nanosecond a pixel, a leaf's projection some tens.
const OOR_SCAN_PER_LEAF: u64 = 64;

/// What [`mark`] found: the done-mask, and its counts.
pub(super) struct Marked {
    /// Per pixel: unfinished and inside the screen polygon of some far leaf (gets a ray).
    pub mask: Vec<bool>,
    /// Far leaves whose box projected to a polygon or to the whole screen, counted in each
    /// band of rows the polygon meets ([`mark`]).
    pub polygons: u64,
    /// Far instances skipped whole: their box's rectangle held no pixel left to mark, counted
    /// in each band of rows the rectangle meets.
    pub instances_skipped: u64,
}

/// A far instance's run of leaves in the list (`first..end`), with what decides whether it
/// may be skipped whole: the pixel rectangle of its box, grown by a pixel, when it is small
/// enough for a scan to cost less than its leaves' projections ([`OOR_SCAN_PER_LEAF`]).
struct Run {
    first: usize,
    end: usize,
    skippable: Option<[u32; 4]>,
}

/// §III.C: the done-mask of `cast_mask` (the unfinished pixels of a `w × h` frame): the
/// pixels inside the screen polygon of a far leaf (`far`: instance and leaf, an instance's
/// leaves in one run; `instances` place them, `accel` holds their octrees), seen from `eye`
/// with the near plane at `near`.
///
/// Marked in `bands` bands of rows at once, on the threads of the pool this runs in: each
/// band meets the far instances in the same order (each instance's box projected once, before)
/// and marks only its own rows. The mask does not depend on the bands; a leaf whose polygon
/// spans several bands is projected, and counted, in each.
#[allow(clippy::too_many_arguments)]
pub(super) fn mark(
    cast_mask: &[bool],
    far: &[(u32, u32)],
    instances: &[(InstanceRec, ItemId, Mat4)],
    accel: &[Accel],
    eye: Vec3,
    [w, h]: [u32; 2],
    near: f32,
    bands: u32,
) -> Marked {
    debug_assert_eq!(cast_mask.len(), w as usize * h as usize, "a mask of the frame's pixels");
    // The far list holds an instance's leaves in one run. The runs go nearest instance
    // first, so that the leaves in front mark the pixels that those behind then find
    // marked; an instance whose box lies (when small enough for the scan to cost less
    // than its leaves' projections) on pixels all finished or marked is skipped whole.
    // The mask is the same in any order.
    let mut runs: Vec<(f32, Run)> = Vec::new();
    let mut first = 0;
    while first < far.len() {
        let inst = far[first].0;
        let end = first + far[first..].iter().take_while(|&&(i, _)| i == inst).count();
        let (rec, _, clip) = &instances[inst as usize];
        if let Accel::Mesh { octree, .. } = &accel[rec.node.index()] {
            let b = octree.bounds().transformed(&rec.world_from_object);
            // Judged with twice the near margin: an instance skipped has no corner near
            // enough for a leaf of it to cover the screen, however its corners round.
            let skippable = match project_box(clip, &octree.bounds(), w, h, 2.0 * near) {
                Projection::Nothing | Projection::Screen => None,
                Projection::Polygon { rect, .. } => {
                    // Grown by a pixel: a leaf's corners, summed otherwise, may round past
                    // the instance's rectangle where their faces meet.
                    let rect = [
                        rect[0].saturating_sub(1),
                        (rect[1] + 1).min(w - 1),
                        rect[2].saturating_sub(1),
                        (rect[3] + 1).min(h - 1),
                    ];
                    let area = u64::from(rect[1] - rect[0] + 1) * u64::from(rect[3] - rect[2] + 1);
                    (area <= OOR_SCAN_PER_LEAF * (end - first) as u64).then_some(rect)
                }
            };
            let run = Run { first, end, skippable };
            runs.push((eye.clamp(b.min, b.max).distance_squared(eye), run));
        }
        first = end;
    }
    runs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut done = vec![false; cast_mask.len()];
    if done.is_empty() {
        return Marked {
            mask: done,
            polygons: 0,
            instances_skipped: 0,
        };
    }
    let rows = h.div_ceil(bands.clamp(1, h)).max(1);
    let counts: Vec<(u64, u64)> = done
        .par_chunks_mut((rows * w) as usize)
        .enumerate()
        .map(|(k, band)| {
            let y0 = k as u32 * rows;
            let band = Band {
                cast_mask,
                done: band,
                w,
                h,
                y0,
                y1: (y0 + rows).min(h) - 1,
            };
            band.mark(&runs, far, instances, accel, near)
        })
        .collect();
    Marked {
        mask: done,
        polygons: counts.iter().map(|c| c.0).sum(),
        instances_skipped: counts.iter().map(|c| c.1).sum(),
    }
}

/// The rows `y0..=y1` of the done-mask being marked ([`mark`]): `done` holds them, and
/// `cast_mask` the whole frame.
struct Band<'a> {
    cast_mask: &'a [bool],
    done: &'a mut [bool],
    w: u32,
    h: u32,
    y0: u32,
    y1: u32,
}

impl Band<'_> {
    /// The pixel rectangle `rect` (inclusive) cut to the band's rows, or `None` when it has
    /// none of them.
    fn cut(&self, rect: [u32; 4]) -> Option<[u32; 4]> {
        let (y0, y1) = (rect[2].max(self.y0), rect[3].min(self.y1));
        (y0 <= y1).then_some([rect[0], rect[1], y0, y1])
    }

    /// Whether the rectangle `rect` (inclusive, within the band's rows) holds a pixel left to
    /// mark: one whose rectangle holds none marks nothing (seen from outside a city, most far
    /// leaves lie behind marked ones), and needs no hull.
    fn open(&self, rect: [u32; 4]) -> bool {
        (rect[2]..=rect[3]).any(|y| {
            let row = (y * self.w) as usize;
            let local = ((y - self.y0) * self.w) as usize;
            let span = rect[0] as usize..=rect[1] as usize;
            self.cast_mask[row + span.start()..=row + span.end()]
                .iter()
                .zip(&self.done[local + span.start()..=local + span.end()])
                .any(|(&c, &d)| c && !d)
        })
    }

    /// Marks the band from the far leaves of `runs` (sorted, nearest instance first), as
    /// [`mark`] says; its counts of polygons and instances skipped.
    fn mark(
        self,
        runs: &[(f32, Run)],
        far: &[(u32, u32)],
        instances: &[(InstanceRec, ItemId, Mat4)],
        accel: &[Accel],
        near: f32,
    ) -> (u64, u64) {
        let (w, h) = (self.w, self.h);
        let (mut polygons, mut instances_skipped) = (0u64, 0u64);
        'runs: for (_, run) in runs {
            let (rec, _, clip) = &instances[far[run.first].0 as usize];
            let Accel::Mesh { octree, .. } = &accel[rec.node.index()] else {
                continue;
            };
            if let Some(rect) = run.skippable {
                // Its leaves lie within the rectangle: none of them reaches a band it misses.
                let Some(rect) = self.cut(rect) else {
                    continue;
                };
                if !self.open(rect) {
                    instances_skipped += 1;
                    continue;
                }
            }
            for &(_, leaf) in &far[run.first..run.end] {
                let b = octree.nodes()[leaf as usize].bounds;
                match project_box(clip, &b, w, h, near) {
                    Projection::Nothing => {}
                    Projection::Screen => {
                        polygons += 1;
                        let rows = (self.y0 * w) as usize..((self.y1 + 1) * w) as usize;
                        self.done.copy_from_slice(&self.cast_mask[rows]);
                        break 'runs;
                    }
                    Projection::Polygon { corners, rect } => {
                        let Some(rect) = self.cut(rect) else {
                            continue;
                        };
                        polygons += 1;
                        if !self.open(rect) {
                            continue;
                        }
                        let hull = Hull::of(corners);
                        for y in rect[2]..=rect[3] {
                            let local = ((y - self.y0) * w) as usize;
                            for x in rect[0]..=rect[1] {
                                let i = (y * w + x) as usize;
                                let d = &mut self.done[local + x as usize];
                                if self.cast_mask[i] && !*d && hull.inside(x as f32 + 0.5, y as f32 + 0.5) {
                                    *d = true;
                                }
                            }
                        }
                    }
                }
            }
        }
        (polygons, instances_skipped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::Vec3;

    #[test]
    fn projected_box_holds_its_projected_points() {
        let (view, m) = crate::test_view(Vec3::new(3.0, 2.0, 5.0), Vec3::ZERO, 64, 48);
        let b = Aabb::new(Vec3::splat(-0.5), Vec3::new(0.5, 1.0, 0.25));
        let Projection::Polygon { corners, rect } = project_box(&m, &b, 64, 48, view.camera().near) else {
            panic!("box in view")
        };
        let hull = Hull::of(corners);
        assert!((4..=6).contains(&hull.points().len()), "{} sides", hull.points().len());
        for i in 0..=10 {
            for j in 0..=10 {
                for k in 0..=10 {
                    let p = b.min + b.size() * Vec3::new(i as f32, j as f32, k as f32) / 10.0;
                    let c = m * p.extend(1.0);
                    let x = (c.x / c.w * 0.5 + 0.5) * 64.0;
                    let y = (0.5 - c.y / c.w * 0.5) * 48.0;
                    assert!(hull.inside(x, y));
                    assert!(x >= rect[0] as f32 - 0.5 && x <= rect[1] as f32 + 1.5);
                }
            }
        }
        assert!(!hull.inside(-100.0, -100.0));
    }

    #[test]
    fn box_around_the_eye_covers_the_screen_and_box_behind_covers_nothing_visible() {
        let (_, m) = crate::test_view(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 64, 48);
        let around = Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0));
        assert!(matches!(project_box(&m, &around, 64, 48, 0.1), Projection::Screen));
        let aside = Aabb::new(Vec3::new(100.0, 0.0, -2.0), Vec3::new(101.0, 1.0, -1.0));
        assert!(matches!(project_box(&m, &aside, 64, 48, 0.1), Projection::Nothing));
    }
}
