//! Scalar triangle setup: the per-triangle path from projected corners to a [`TriSetup`]
//! (trivial reject, clip, snap, box, orientation, depth plane), and the walk over a draw's
//! triangle stream that feeds it (or the 8-lane setup, [`super::setup8`]).

use super::project::{clip_and_setup, ProjVertex, VertexCache, Viewport, NEEDS_CLIP, NOT_FINITE, OUT_OF_VIEW};
#[cfg(target_arch = "x86_64")]
use super::setup8;
use super::sinks::SetupSink;
use super::{Draw, DrawTriangles, HALF, MAX_CLUSTER_VERTICES, SUB, SUBPIXEL_BITS};
use occult_core::{ItemId, Mat4, Vec3};
use std::ops::Range;

/// A triangle ready to scan: its snapped corners (1/256 pixel, oriented so that the edge
/// functions are non-negative inside), its pixel box, and its depth plane anchored at the centre
/// of pixel `(px0, py0)`. One cache line: the tile-binned scan re-derives the edge functions
/// from the corners, which costs less than moving them through memory (the direct sink takes
/// them from the 8-lane setup for small boxes, where they are at hand).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct TriSetup {
    pub(super) x: [i32; 3],
    pub(super) y: [i32; 3],
    pub(super) px0: u16,
    pub(super) py0: u16,
    pub(super) px1: u16,
    pub(super) py1: u16,
    /// Depth at the centre of pixel `(px0, py0)`.
    pub(super) zc: f32,
    pub(super) dzdx: f32,
    pub(super) dzdy: f32,
    pub(super) zmin: f32,
    pub(super) zmax: f32,
    /// Larger side of the snapped corners' box, in whole pixels (saturating): decides whether
    /// edge functions fit i32 lanes. The pixel box above is clamped to the frame and says nothing
    /// about that: a triangle reaching into the guard band can show a tiny box on screen.
    pub(super) extent: u16,
    /// Counter-clockwise on screen before the corners were reordered (a front face); read by
    /// the stencil pass, which counts by orientation.
    pub(super) front: bool,
    pub(super) item: ItemId,
}

const _: () = assert!(std::mem::size_of::<TriSetup>() == 64);
// Pixel boxes are stored in u16.
const _: () = assert!(occult_core::MAX_RESOLUTION <= u16::MAX as u32);

/// The triangle stream of one pass: the triangles of `draws` one after the other, draw `d`'s
/// first at index `draw_starts[d]` ([`draw_starts`]: one more entry than draws, the last the
/// stream's length); the corners of whole-mesh draws projected ahead in `vertices`, draw `d`'s
/// from `vertex_offsets[d]` (other draws project theirs as they are set up).
#[derive(Clone, Copy)]
pub(super) struct TriStream<'a> {
    pub(super) draws: &'a [Draw<'a>],
    pub(super) draw_starts: &'a [usize],
    pub(super) vertex_offsets: &'a [usize],
    pub(super) vertices: &'a [ProjVertex],
}

impl<'a> TriStream<'a> {
    /// The stream of `draws`, with `draw_starts` from [`draw_starts`] and one entry of
    /// `vertex_offsets` a draw.
    pub(super) fn new(
        draws: &'a [Draw<'a>],
        draw_starts: &'a [usize],
        vertex_offsets: &'a [usize],
        vertices: &'a [ProjVertex],
    ) -> Self {
        debug_assert_eq!(draw_starts.len(), draws.len() + 1);
        debug_assert_eq!(vertex_offsets.len(), draws.len());
        Self {
            draws,
            draw_starts,
            vertex_offsets,
            vertices,
        }
    }

    /// Triangles in the stream.
    pub(super) fn len(&self) -> usize {
        self.draw_starts[self.draws.len()]
    }
}

/// Index in the stream of each draw's first triangle, then the stream's length (one more entry
/// than draws).
pub(super) fn draw_starts(draws: &[Draw<'_>]) -> Vec<usize> {
    let mut starts = Vec::with_capacity(draws.len() + 1);
    let mut total = 0usize;
    for d in draws {
        starts.push(total);
        total += d.triangles.len(d.mesh);
    }
    starts.push(total);
    starts
}

/// Sets up the triangles `range` of the pass's `stream` and hands them to `out`: one by one, or
/// with `AVX2` (only where the processor has it) eight at a time through [`setup8::Batch`].
#[inline(always)]
pub(super) fn setup_range<const AVX2: bool>(
    vp: &Viewport,
    stream: &TriStream<'_>,
    range: Range<usize>,
    out: &mut impl SetupSink,
) {
    let TriStream {
        draws,
        draw_starts,
        vertex_offsets,
        vertices,
    } = *stream;
    let mut d = draw_starts.partition_point(|&s| s <= range.start) - 1;
    let mut t = range.start;
    let mut cache = VertexCache::new();
    #[cfg(target_arch = "x86_64")]
    let mut batch = setup8::Batch::new();
    // Where the 8-lane setup runs, each triangle joins the batch (flushed when full); the
    // scalar setup takes it at once otherwise.
    let mut emit = |v: [&ProjVertex; 3], indices: [u32; 3], d: usize, item: ItemId, out: &mut _| {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // Trivial rejects (most of a scene outside the view) never take a lane.
            if v[0].code & v[1].code & v[2].code & OUT_OF_VIEW != 0
                || (v[0].code | v[1].code | v[2].code) & NOT_FINITE != 0
            {
                return;
            }
            batch.push(v, d, item);
            if batch.is_full() {
                // SAFETY: the AVX2 instantiation only runs where the dispatcher found AVX2.
                unsafe { setup8::setup8_avx2(vp, draws, &mut batch, out) };
            }
            return;
        }
        let draw = &draws[d];
        let corners = || indices.map(|i| draw.mesh.positions()[i as usize]);
        setup_triangle(vp, v.map(|p| *p), &draw.clip_from_object, corners, item, out);
    };
    // A cluster's projected vertices (made once a range: a draw of one small cluster would
    // otherwise clear it for a few triangles).
    let mut local = [ProjVertex::default(); MAX_CLUSTER_VERTICES];
    while t < range.end {
        while draw_starts[d + 1] <= t {
            d += 1;
        }
        let draw = &draws[d];
        let end = draw_starts[d + 1].min(range.end);
        let mesh = draw.mesh;
        let tris = mesh.triangles();
        // Read once a draw: the stream comes through a reference, so the compiler cannot tell
        // that the sink's writes leave the draws be, and would reload it per triangle.
        let first_item = draw.first_item;
        match &draw.triangles {
            DrawTriangles::All => {
                let verts = &vertices[vertex_offsets[d]..vertex_offsets[d] + mesh.positions().len()];
                let first = t - draw_starts[d];
                for (j, &[i0, i1, i2]) in tris[first..end - draw_starts[d]]
                    .iter()
                    .enumerate()
                    .map(|(k, t)| (first + k, t))
                {
                    // SAFETY: `verts` holds one entry per position of the mesh (sliced with a
                    // check above), and `Mesh` guarantees that every index names a position
                    // (checked by `Mesh::new`, its only constructor; fields private, see its
                    // doc). The loop runs once per triangle of the scene, where three bounds
                    // checks are a sizeable share of its instructions.
                    debug_assert!([i0, i1, i2].iter().all(|&i| (i as usize) < verts.len()));
                    let v = unsafe {
                        [
                            verts.get_unchecked(i0 as usize),
                            verts.get_unchecked(i1 as usize),
                            verts.get_unchecked(i2 as usize),
                        ]
                    };
                    emit(v, [i0, i1, i2], d, first_item + j as u64, out);
                }
            }
            #[cfg(target_arch = "x86_64")]
            DrawTriangles::Clusters { meshlets, list } if AVX2 => {
                // Each cluster's vertices projected once, eight at a time, into `local`; its
                // triangles then read their corners there (a range may begin or end inside a
                // cluster: it is projected whole).
                let m = &draw.clip_from_object;
                let (mut j, last) = (t - draw_starts[d], end - draw_starts[d]);
                let (mut k, mut base) = meshlets.seek(list, j);
                while j < last {
                    let c = list[k] as usize;
                    let n = meshlets.triangle_count(c);
                    let (_, first) = meshlets.cluster(c);
                    // The cluster's positions lie in a row, padded to whole lanes: loaded as
                    // they are, no gather.
                    let p = meshlets.positions(c);
                    for (chunk, out) in p.chunks_exact(setup8::LANES).zip(local.chunks_exact_mut(setup8::LANES)) {
                        // SAFETY: the AVX2 instantiation only runs where the dispatcher found AVX2.
                        unsafe { setup8::project8_avx2(vp, m, chunk, out) };
                    }
                    let to = (base + n).min(last);
                    for i in first + (j - base)..first + (to - base) {
                        let (corner, ti) = meshlets.triangle(i);
                        let v = corner.map(|a| &local[a as usize]);
                        emit(v, tris[ti as usize], d, first_item + ti as u64, out);
                    }
                    j = to;
                    base += n;
                    k += 1;
                }
            }
            DrawTriangles::Clusters { meshlets, list } => {
                let m = &draw.clip_from_object;
                let (mut j, last) = (t - draw_starts[d], end - draw_starts[d]);
                let (mut k, mut base) = meshlets.seek(list, j);
                while j < last {
                    let c = list[k] as usize;
                    let n = meshlets.triangle_count(c);
                    let (verts, first) = meshlets.cluster(c);
                    for (slot, &p) in local.iter_mut().zip(&meshlets.positions(c)[..verts.len()]) {
                        *slot = vp.project(m, p);
                    }
                    let to = (base + n).min(last);
                    for i in first + (j - base)..first + (to - base) {
                        let (corner, ti) = meshlets.triangle(i);
                        let v = corner.map(|a| &local[a as usize]);
                        emit(v, tris[ti as usize], d, first_item + ti as u64, out);
                    }
                    j = to;
                    base += n;
                    k += 1;
                }
            }
            #[cfg(target_arch = "x86_64")]
            sel if AVX2 => {
                // Corners projected eight at a time, in lanes: cheaper than the cache below even
                // when every corner is shared by six triangles.
                let pos = mesh.positions();
                let m = &draw.clip_from_object;
                let (mut j, last) = (t - draw_starts[d], end - draw_starts[d]);
                while j < last {
                    let n = (last - j).min(setup8::LANES);
                    // Lists of a hierarchy's leaves read the mesh out of order: fetch the
                    // triangles four batches ahead and the corners two ahead (whose triangles
                    // were fetched two batches ago) while this one is set up.
                    for k in (j + 2 * setup8::LANES)..(j + 3 * setup8::LANES).min(last) {
                        let [i0, i1, i2] = tris[sel.triangle_index(k) as usize];
                        prefetch_read(&pos[i0 as usize]);
                        prefetch_read(&pos[i1 as usize]);
                        prefetch_read(&pos[i2 as usize]);
                    }
                    for k in (j + 4 * setup8::LANES)..(j + 5 * setup8::LANES).min(last) {
                        prefetch_read(&tris[sel.triangle_index(k) as usize]);
                    }
                    let mut triangle = [0u32; setup8::LANES];
                    let mut indices = [[0u32; 3]; setup8::LANES];
                    let mut corners = [[Vec3::ZERO; setup8::LANES]; 3];
                    for k in 0..n {
                        triangle[k] = sel.triangle_index(j + k);
                        indices[k] = tris[triangle[k] as usize];
                        for c in 0..3 {
                            corners[c][k] = pos[indices[k][c] as usize];
                        }
                    }
                    let mut v = [[ProjVertex::default(); setup8::LANES]; 3];
                    for c in 0..3 {
                        // SAFETY: the AVX2 instantiation only runs where the dispatcher found AVX2.
                        unsafe { setup8::project8_avx2(vp, m, &corners[c], &mut v[c]) };
                    }
                    for k in 0..n {
                        let item = first_item + triangle[k] as u64;
                        emit([&v[0][k], &v[1][k], &v[2][k]], indices[k], d, item, out);
                    }
                    j += n;
                }
            }
            sel => {
                let pos = mesh.positions();
                let m = &draw.clip_from_object;
                cache.reset();
                for j in (t - draw_starts[d])..(end - draw_starts[d]) {
                    let ti = sel.triangle_index(j);
                    let [i0, i1, i2] = tris[ti as usize];
                    let v = [
                        cache.project(vp, m, pos, i0),
                        cache.project(vp, m, pos, i1),
                        cache.project(vp, m, pos, i2),
                    ];
                    emit([&v[0], &v[1], &v[2]], [i0, i1, i2], d, first_item + ti as u64, out);
                }
            }
        }
        t = end;
    }
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: as above.
        unsafe { setup8::setup8_avx2(vp, draws, &mut batch, out) };
    }
}

#[inline(always)]
pub(super) fn setup_triangle(
    vp: &Viewport,
    v: [ProjVertex; 3],
    clip_from_object: &Mat4,
    corners: impl FnOnce() -> [Vec3; 3],
    item: ItemId,
    out: &mut impl SetupSink,
) {
    let or = v[0].code | v[1].code | v[2].code;
    if v[0].code & v[1].code & v[2].code & OUT_OF_VIEW != 0 || or & NOT_FINITE != 0 {
        return;
    }
    if or & NEEDS_CLIP != 0 {
        clip_and_setup(vp, clip_from_object, corners(), item, out);
        return;
    }
    setup_snapped(
        vp,
        [
            (v[0].x, v[0].y, v[0].z),
            (v[1].x, v[1].y, v[1].z),
            (v[2].x, v[2].y, v[2].z),
        ],
        item,
        out,
    );
}

/// Sets up a triangle from snapped vertices `(x, y, z)` and hands it to `out`; false when
/// there is nothing to scan (no pixel centre in its box, no area, facing away, beyond far).
#[inline(always)]
pub(super) fn setup_snapped(vp: &Viewport, v: [(i32, i32, f32); 3], item: ItemId, out: &mut impl SetupSink) -> bool {
    let (x0, y0) = (v[0].0 as i64, v[0].1 as i64);
    let (mut x1, mut y1, mut z1) = (v[1].0 as i64, v[1].1 as i64, v[1].2);
    let (mut x2, mut y2, mut z2) = (v[2].0 as i64, v[2].1 as i64, v[2].2);
    let z0 = v[0].2;
    // Pixel box: centres (i + 1/2) inside [min, max] of the snapped corners.
    let minx = x0.min(x1).min(x2);
    let maxx = x0.max(x1).max(x2);
    let miny = y0.min(y1).min(y2);
    let maxy = y0.max(y1).max(y2);
    let px0 = ((minx - HALF + SUB - 1) >> SUBPIXEL_BITS).max(0);
    let px1 = ((maxx - HALF) >> SUBPIXEL_BITS).min(vp.width as i64 - 1);
    let py0 = ((miny - HALF + SUB - 1) >> SUBPIXEL_BITS).max(0);
    let py1 = ((maxy - HALF) >> SUBPIXEL_BITS).min(vp.height as i64 - 1);
    if px0 > px1 || py0 > py1 {
        return false;
    }
    out.will_touch(px0 as u32, py0 as u32, py1 > py0);
    let mut area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    if area == 0 {
        return false;
    }
    // On screen (y down) a counter-clockwise front face has negative area.
    if area > 0 && vp.cull_backfaces {
        return false;
    }
    let front = area < 0;
    if area < 0 {
        std::mem::swap(&mut x1, &mut x2);
        std::mem::swap(&mut y1, &mut y2);
        std::mem::swap(&mut z1, &mut z2);
        area = -area;
    }
    let zmin = min_f32(min_f32(z0, z1), z2);
    let zmax = max_f32(max_f32(z0, z1), z2);
    if zmax < vp.far_depth {
        return false;
    }
    // Depth plane in pixel units, relative to corner 0, computed in f64; anchored at the centre
    // of pixel (px0, py0) and stored in f32.
    let inv = 1.0 / (area as f64 / (SUB * SUB) as f64);
    let (fx1, fy1) = ((x1 - x0) as f64 / SUB as f64, (y1 - y0) as f64 / SUB as f64);
    let (fx2, fy2) = ((x2 - x0) as f64 / SUB as f64, (y2 - y0) as f64 / SUB as f64);
    let (dz1, dz2) = ((z1 - z0) as f64, (z2 - z0) as f64);
    let dzdx = (dz1 * fy2 - dz2 * fy1) * inv;
    let dzdy = (fx1 * dz2 - fx2 * dz1) * inv;
    let zc = z0 as f64
        + dzdx * ((px0 as f64 + 0.5) - x0 as f64 / SUB as f64)
        + dzdy * ((py0 as f64 + 0.5) - y0 as f64 / SUB as f64);
    out.push(
        vp,
        TriSetup {
            x: [x0 as i32, x1 as i32, x2 as i32],
            y: [y0 as i32, y1 as i32, y2 as i32],
            px0: px0 as u16,
            py0: py0 as u16,
            px1: px1 as u16,
            py1: py1 as u16,
            zc: zc as f32,
            dzdx: dzdx as f32,
            dzdy: dzdy as f32,
            zmin,
            zmax,
            extent: (((maxx - minx).max(maxy - miny) >> SUBPIXEL_BITS) + 1).min(u16::MAX as i64) as u16,
            front,
            item,
        },
    );
    true
}

/// The smaller of `a` and `b`, `b` when they compare equal or either is NaN: the rule of
/// `minps`, which the 8-lane setup uses (`f32::min` leaves the sign of a zero unspecified).
#[inline(always)]
pub(super) fn min_f32(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The larger of `a` and `b`, by the rule of `maxps` (see [`min_f32`]).
#[inline(always)]
pub(super) fn max_f32(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// Hints the processor to fetch `x`'s cache line; never faults, never changes results.
#[inline(always)]
fn prefetch_read<T>(x: &T) {
    occult_core::simd::prefetch(x as *const T);
}
