//! Projection and clipping: vertices to clip space, outcodes and snapped screen positions,
//! the per-draw vertex cache of index-list draws, and the homogeneous clipping of the rare
//! triangle that crosses the near plane or the guard band.

use super::setup::{setup_snapped, TriSetup};
#[cfg(target_arch = "x86_64")]
use super::setup8;
use super::sinks::SetupSink;
use super::{RasterConfig, GUARD_PIXELS, SUB};
use occult_core::glam::DVec4;
use occult_core::{ItemId, Mat4, Vec3, Vec4, View};

pub(super) const OUT_LEFT: u32 = 1;
pub(super) const OUT_RIGHT: u32 = 2;
pub(super) const OUT_BOTTOM: u32 = 4;
pub(super) const OUT_TOP: u32 = 8;
pub(super) const OUT_NEAR: u32 = 16;
pub(super) const OUT_OF_VIEW: u32 = OUT_LEFT | OUT_RIGHT | OUT_BOTTOM | OUT_TOP | OUT_NEAR;
pub(super) const NEEDS_CLIP: u32 = 32;
pub(super) const NOT_FINITE: u32 = 64;

/// A vertex in clip space with its snapped screen position. The 8-lane setup loads and stores
/// it as one 16-byte vector of these four fields, in this order.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
pub(super) struct ProjVertex {
    pub(super) x: i32,
    pub(super) y: i32,
    pub(super) z: f32,
    pub(super) code: u32,
}

const _: () = assert!(std::mem::size_of::<ProjVertex>() == 16);

/// Per-frame constants.
#[derive(Clone, Copy, Debug)]
pub(super) struct Viewport {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) fwidth: f32,
    pub(super) fheight: f32,
    pub(super) guard_x: f32,
    pub(super) guard_y: f32,
    pub(super) far_depth: f32,
    pub(super) tile_size: u32,
    pub(super) tile_shift: u32,
    pub(super) tiles_x: u32,
    pub(super) tiles_y: u32,
    pub(super) cull_backfaces: bool,
    /// The inclusive pixel box drawn, `[x0, y0, x1, y1]`: the view's region
    /// ([`View::with_region`]; the whole frame for most views).
    pub(super) region: [u32; 4],
    /// The region's left and right in `x_ndc` and its bottom and top in `y_ndc`, a pixel wider
    /// (`±1` at the frame's own edges): a vertex beyond is out of the region's view
    /// (`OUT_LEFT` ...), so that a triangle wholly beside a region is rejected before its setup.
    pub(super) band_ndc: [f32; 4],
}

impl Viewport {
    pub(super) fn new(view: &View, config: &RasterConfig) -> Self {
        let (width, height) = (view.width(), view.height());
        let tile_size = config.tile_size;
        Self {
            width,
            height,
            fwidth: width as f32,
            fheight: height as f32,
            guard_x: 2.0 * GUARD_PIXELS / width as f32 - 1.0,
            guard_y: 2.0 * GUARD_PIXELS / height as f32 - 1.0,
            far_depth: view.far_depth(),
            tile_size,
            tile_shift: tile_size.trailing_zeros(),
            tiles_x: width.div_ceil(tile_size),
            tiles_y: height.div_ceil(tile_size),
            cull_backfaces: config.cull_backfaces,
            region: [
                view.columns().start,
                view.rows().start,
                view.columns().end - 1,
                view.rows().end - 1,
            ],
            band_ndc: band_ndc(view),
        }
    }

    /// The inclusive pixel rectangle of tile `tile` (tiles row-major, `tiles_x` a row; the
    /// last row and column clipped to the frame).
    #[inline(always)]
    pub(super) fn tile_rect(&self, tile: usize) -> [u32; 4] {
        let tx = tile as u32 % self.tiles_x;
        let ty = tile as u32 / self.tiles_x;
        [
            tx * self.tile_size,
            ty * self.tile_size,
            ((tx + 1) * self.tile_size).min(self.width) - 1,
            ((ty + 1) * self.tile_size).min(self.height) - 1,
        ]
    }

    #[inline(always)]
    pub(super) fn project(&self, clip_from_object: &Mat4, p: Vec3) -> ProjVertex {
        self.project_clip(to_clip(clip_from_object, p))
    }

    /// Outcodes and, when no clipping is needed, the snapped screen position and depth.
    #[inline(always)]
    pub(super) fn project_clip(&self, c: Vec4) -> ProjVertex {
        let mut code = 0;
        if !c.is_finite() {
            return ProjVertex {
                x: 0,
                y: 0,
                z: 0.0,
                code: NOT_FINITE,
            };
        }
        code |= if c.x < self.band_ndc[0] * c.w { OUT_LEFT } else { 0 };
        code |= if c.x > self.band_ndc[1] * c.w { OUT_RIGHT } else { 0 };
        code |= if c.y < self.band_ndc[2] * c.w { OUT_BOTTOM } else { 0 };
        code |= if c.y > self.band_ndc[3] * c.w { OUT_TOP } else { 0 };
        code |= if c.z > c.w || c.w <= 0.0 {
            OUT_NEAR | NEEDS_CLIP
        } else {
            0
        };
        if c.x.abs() > self.guard_x * c.w || c.y.abs() > self.guard_y * c.w {
            code |= NEEDS_CLIP;
        }
        if code & NEEDS_CLIP != 0 {
            return ProjVertex {
                x: 0,
                y: 0,
                z: 0.0,
                code,
            };
        }
        let inv_w = 1.0 / c.w;
        let sx = (c.x * inv_w * 0.5 + 0.5) * self.fwidth;
        let sy = (0.5 - c.y * inv_w * 0.5) * self.fheight;
        let z = c.z * inv_w;
        // A `w` so small that its inverse overflows (no guard band test catches a vertex on the
        // axis) leaves nothing to draw.
        if !(sx.is_finite() && sy.is_finite() && z.is_finite()) {
            return ProjVertex {
                x: 0,
                y: 0,
                z: 0.0,
                code: NOT_FINITE,
            };
        }
        ProjVertex {
            x: snap(sx),
            y: snap(sy),
            z,
            code,
        }
    }
}

/// [`Viewport::band_ndc`] of `view`: screen column `sx` is `x_ndc = 2 sx / width - 1`, row `sy`
/// is `y_ndc = 1 - 2 sy / height`. Each bound is a plane through the eye (`x = t·w` in clip
/// space), so a triangle whose corners all lie beyond one lies wholly beyond, whatever their
/// `w`.
fn band_ndc(view: &View) -> [f32; 4] {
    let (w, h) = (view.width() as f32, view.height() as f32);
    let (x, y) = (view.columns(), view.rows());
    let left = if x.start == 0 {
        -1.0
    } else {
        2.0 * (x.start as f32 - 1.0) / w - 1.0
    };
    let right = if x.end >= view.width() {
        1.0
    } else {
        2.0 * (x.end as f32 + 1.0) / w - 1.0
    };
    let bottom = if y.end >= view.height() {
        -1.0
    } else {
        1.0 - 2.0 * (y.end as f32 + 1.0) / h
    };
    let top = if y.start == 0 {
        1.0
    } else {
        1.0 - 2.0 * (y.start as f32 - 1.0) / h
    };
    [left, right, bottom, top]
}

/// Object to clip space: the one expression every path uses, so that a vertex recomputed for
/// clipping has the same bits as when it was first projected.
#[inline(always)]
pub(super) fn to_clip(clip_from_object: &Mat4, p: Vec3) -> Vec4 {
    *clip_from_object * p.extend(1.0)
}

/// Rounds a screen coordinate to the fixed-point grid (to nearest, ties to even), without
/// depending on SSE4.1's `roundss`.
#[inline(always)]
pub(super) fn snap(v: f32) -> i32 {
    snap64(v as f64)
}

/// [`snap`] of a coordinate computed in f64 (a corner made by clipping).
#[inline(always)]
pub(super) fn snap64(v: f64) -> i32 {
    const MAGIC: f64 = 6755399441055744.0; // 1.5 · 2^52
    ((v * SUB as f64 + MAGIC) - MAGIC) as i32
}

/// Projects `positions` into `out` (as many as `out` holds): one by one, or with `AVX2` (only
/// inside the AVX2 entry point, [`super::dispatch::project_all`]) eight at a time in lanes.
#[inline(always)]
pub(super) fn project_all<const AVX2: bool>(
    vp: &Viewport,
    clip_from_object: &Mat4,
    positions: &[Vec3],
    out: &mut [ProjVertex],
) {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        let n = out.len().min(positions.len());
        let whole = n - n % setup8::LANES;
        for (o, p) in out[..whole]
            .chunks_exact_mut(setup8::LANES)
            .zip(positions.chunks_exact(setup8::LANES))
        {
            // SAFETY: the AVX2 instantiation only runs where the dispatcher found AVX2; the
            // chunks hold eight each.
            unsafe { setup8::project8_avx2(vp, clip_from_object, p, o) };
        }
        return project_all::<false>(vp, clip_from_object, &positions[whole..n], &mut out[whole..n]);
    }
    for (o, &p) in out.iter_mut().zip(positions) {
        *o = vp.project(clip_from_object, p);
    }
}

/// Entries of [`VertexCache`] (a power of two).
pub(super) const VERTEX_CACHE: usize = 64;

/// Projected vertices of the current index-list or range draw, direct-mapped by vertex index:
/// the triangles of a list share corners (a quad's two triangles share two, a strip's or a
/// fan's more), and a draw's indices are mostly runs of neighbours, so most shared corners are
/// projected once per draw instead of once per triangle, as a whole-mesh draw's are. Results
/// are unchanged: a projection is a function of the matrix and the position alone.
pub(super) struct VertexCache {
    /// Vertex index held by each entry; `u32::MAX` (never an index: meshes have fewer than
    /// `u32::MAX` vertices) when empty.
    pub(super) tags: [u32; VERTEX_CACHE],
    pub(super) vertices: [ProjVertex; VERTEX_CACHE],
}

impl VertexCache {
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            tags: [u32::MAX; VERTEX_CACHE],
            vertices: [ProjVertex::default(); VERTEX_CACHE],
        }
    }

    /// Empties the cache (a new draw, a new matrix).
    #[inline(always)]
    pub(super) fn reset(&mut self) {
        self.tags = [u32::MAX; VERTEX_CACHE];
    }

    /// Vertex `i` of `positions` projected by `m`, from the cache when it holds it.
    #[inline(always)]
    pub(super) fn project(&mut self, vp: &Viewport, m: &Mat4, positions: &[Vec3], i: u32) -> ProjVertex {
        let slot = i as usize & (VERTEX_CACHE - 1);
        if self.tags[slot] != i {
            self.tags[slot] = i;
            self.vertices[slot] = vp.project(m, positions[i as usize]);
        }
        self.vertices[slot]
    }
}

/// Clips a triangle (object-space corners `p` under `clip_from_object`) against the near plane
/// and the guard band in homogeneous space and sets up the fan of the resulting polygon.
///
/// The clip coordinates are recomputed and clipped in f64: clipping subtracts those of corners
/// that may lie far apart (a ground plane reaching far past the near plane), and in f32 a new
/// corner's `w` could round to or below 0 and lose the whole triangle. The f64 products of the
/// f32 inputs are exact. A corner that no plane moves is still projected from its f32 clip
/// coordinates, which give it the bits every other path gives it, so that neighbours meet.
///
/// The pieces are handed to `out` by the caller's inlined code, not from here: this cold
/// function is compiled for the baseline instruction set, and a sink's scan inlined into it
/// would call its AVX2 operations out of line.
#[inline(always)]
pub(super) fn clip_and_setup(
    vp: &Viewport,
    clip_from_object: &Mat4,
    p: [Vec3; 3],
    item: ItemId,
    out: &mut impl SetupSink,
) {
    let pieces = clip_pieces(vp, clip_from_object, p, item);
    let n = pieces.len() as u32;
    for t in pieces {
        out.push(vp, t);
    }
    // One triangle, counted once however many pieces it was cut into.
    out.uncount(n.saturating_sub(1));
}

/// Set-up triangles kept in order (the pieces of a clipped triangle).
struct Pieces(Vec<TriSetup>);

impl SetupSink for Pieces {
    fn push(&mut self, _: &Viewport, t: TriSetup) {
        self.0.push(t);
    }

    fn count_uncovered(&mut self, _: u32) {}

    fn uncount(&mut self, _: u32) {}
}

/// The set-up pieces of a triangle that needs clipping, in order ([`clip_and_setup`]).
#[cold]
fn clip_pieces(vp: &Viewport, clip_from_object: &Mat4, p: [Vec3; 3], item: ItemId) -> Vec<TriSetup> {
    let mut out = Pieces(Vec::new());
    let out = &mut out;
    /// A corner of the clipped polygon: its clip coordinates in f64, and in f32 for a corner
    /// of the triangle itself.
    #[derive(Clone, Copy)]
    struct Corner {
        clip: DVec4,
        original: Option<Vec4>,
    }
    let (gx, gy) = (vp.guard_x as f64, vp.guard_y as f64);
    let planes = [
        DVec4::new(0.0, 0.0, -1.0, 1.0), // near: w - z >= 0
        DVec4::new(-1.0, 0.0, 0.0, gx),  // guard: g·w - x >= 0
        DVec4::new(1.0, 0.0, 0.0, gx),
        DVec4::new(0.0, -1.0, 0.0, gy),
        DVec4::new(0.0, 1.0, 0.0, gy),
    ];
    let m = clip_from_object.as_dmat4();
    let mut poly: Vec<Corner> = p
        .iter()
        .map(|&p| Corner {
            clip: m * p.as_dvec3().extend(1.0),
            original: Some(to_clip(clip_from_object, p)),
        })
        .collect();
    let mut next = Vec::with_capacity(9);
    for plane in planes {
        next.clear();
        for i in 0..poly.len() {
            let a = poly[i];
            let b = poly[(i + 1) % poly.len()];
            let da = plane.dot(a.clip);
            let db = plane.dot(b.clip);
            if da >= 0.0 {
                next.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                // Interpolate from the inside vertex, so a shared edge clips identically.
                let clip = if da >= 0.0 {
                    a.clip + (b.clip - a.clip) * (da / (da - db))
                } else {
                    b.clip + (a.clip - b.clip) * (db / (db - da))
                };
                next.push(Corner { clip, original: None });
            }
        }
        std::mem::swap(&mut poly, &mut next);
        if poly.len() < 3 {
            return Vec::new();
        }
    }
    // A NaN w also fails this test.
    if !poly.iter().all(|c| c.clip.w > 0.0) {
        return Vec::new();
    }
    // Clipped vertices lie on or inside every clip plane up to rounding: project them directly.
    let p: Vec<(i32, i32, f32)> = poly
        .iter()
        .map(|c| match c.original {
            // The expression of `Viewport::project_clip`, for the same bits.
            Some(c) if c.w > 0.0 => {
                let inv_w = 1.0 / c.w;
                let sx = (c.x * inv_w * 0.5 + 0.5) * vp.fwidth;
                let sy = (0.5 - c.y * inv_w * 0.5) * vp.fheight;
                (snap(sx), snap(sy), c.z * inv_w)
            }
            _ => {
                let c = c.clip;
                let sx = (c.x / c.w * 0.5 + 0.5) * vp.width as f64;
                let sy = (0.5 - c.y / c.w * 0.5) * vp.height as f64;
                (snap64(sx), snap64(sy), (c.z / c.w) as f32)
            }
        })
        .collect();
    if p.iter().any(|v| !v.2.is_finite()) || poly.iter().any(|c| !c.clip.is_finite()) {
        return Vec::new();
    }
    for i in 1..p.len() - 1 {
        setup_snapped(vp, [p[0], p[i], p[i + 1]], item, out);
    }
    std::mem::take(&mut out.0)
}
