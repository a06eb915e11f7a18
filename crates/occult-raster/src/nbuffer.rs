//! N-buffers: constant-time depth extrema over any screen rectangle.
//!
//! # References
//! Xavier Décoret, *N-Buffers for efficient depth map query*, Computer Graphics Forum 24(3),
//! 2005 (`papers/n-buffers-decoret-2005.txt`):
//! - §2 "Construction": level 0 is a depth map; level `i + 1` at `(x, y)` is the extremum of
//!   level `i` at `(x, y)`, `(x + 2^i, y)`, `(x, y + 2^i)`, `(x + 2^i, y + 2^i)`; so level `i`
//!   at `(x, y)` holds the extremum of the `2^i × 2^i` square whose first corner is `(x, y)`.
//!   All levels have the depth map's resolution, which need not be a power of two.
//! - §2 "Query": the one-square query (the smallest level whose square covers the rectangle,
//!   one lookup, [`NBuffer::query_one`]) and the four-square cover with the five cases of
//!   Fig. 3 ([`NBuffer::query_four`]).
//! - §3.3 "Finding extents": the *min* variant (extremum = minimum) beside the max one.
//! - §4.2 (remark in parentheses): after a depth change, only the pixels up and to the left of
//!   it (here: smaller `x` and `y`) change in the upper levels: [`NBuffer::update_region`].
//!
//! # Conventions
//! Screen conventions are the raster crate's (row 0 on top, `y` down): the square of level
//! `i` at `(x, y)` is `[x, x + 2^i) × [y, y + 2^i)`, that is it extends right and **down**
//! (the paper's "north and east" in OpenGL's y-up window). Depth is occult's reversed-Z:
//! **greater is nearer**, 0 is empty (infinitely far). So:
//! - [`Extremum::Min`] returns the *least* stored value of a rectangle = its **farthest**
//!   depth. This is what occlusion culling needs (the paper's "max depth" in its z-up
//!   convention): an object whose nearest depth is below it is hidden ([`NBuffer::occludes`]).
//! - [`Extremum::Max`] returns the *greatest* stored value = the **nearest** depth.
//!
//! Results are conservative bounds: a [`Extremum::Max`] query is never below the true maximum
//! of the rectangle, a [`Extremum::Min`] query never above the true minimum (the covering
//! squares contain the rectangle; the paper's "the overlapping of squares is not an issue").
//!
//! # Defined results on odd input
//! - NaN depths are *unknown*, so each variant reads them as its own worst case: `+inf` for
//!   [`Extremum::Max`], `-inf` for [`Extremum::Min`]; every bound stays conservative.
//! - A rectangle is clipped to the map first; an empty or wholly off-screen rectangle holds no
//!   pixel and answers the identity ([`Extremum::identity`]: `-inf` for max, `+inf` for min)
//!   with no lookup. A rectangle larger than the map is the whole map.
//! - A rectangle that needs a level above the ones built answers the extremum of the whole
//!   map (kept at build time, one lookup).
//!
//! # Deviations
//! - Out-of-map neighbours are skipped (each square is clipped to the map) instead of the
//!   paper's border value 0 (`GL_CLAMP_TO_BORDER`): with reversed-Z a 0 border would read as
//!   "infinitely far" and make every min query at the map's edges useless.
//! - The horizontal and vertical passes of §2 are fused per row: a worker takes a band of
//!   output rows, forms the horizontal extremum at offset `2^i` of rows `y` and `y + 2^i` in
//!   registers and keeps their vertical extremum; the intermediate never goes to memory (the
//!   build is bandwidth-bound). Bands run in parallel (rayon). The row kernels (level 0's
//!   key conversion and the four-way extremum) are compiled for the baseline target, AVX2 and
//!   AVX-512BW and chosen at run time (`kernels`); the levels are bit-identical on each
//!   (tested). Computing all levels in one pass over the rows (each level's row as soon as
//!   the two rows it reads are done) was tried and not kept: slower on large maps, no faster
//!   on small ones; one pass per level streams data that stays in the L3 cache at the sizes
//!   of Table 1.
//! - By default the levels stop at `⌈log2 max(w, h)⌉ - 1`, the highest the four-square
//!   query uses (this gives the level counts of the paper's Table 1); a one-square query
//!   above it answers the whole map's extremum.
//! - Levels hold 16-bit keys, not f32 (the paper stored depth textures): the upper half of the
//!   depth's order-preserving bit pattern (sign, exponent, 7 mantissa bits), rounded down for
//!   min and up for max, so every bound stays conservative ([`decode_key`]). This halves the
//!   memory and the build's traffic (the build is bandwidth-bound) and the cache footprint of
//!   queries; the price is a relative depth tolerance of 2^-7 (an object less than 0.8 %
//!   of its distance behind an occluder is not culled).
//! - The Fig. 3 cover is computed with one formula and selects rather than a five-way branch
//!   (random rectangle sizes mispredict the branch); the case-by-case cover is kept and the
//!   two are tested equal. The middle cases of Fig. 3 use two distinct squares: their other
//!   two lookups repeat them (the query always makes four loads; one for a single pixel).
//!   A lookup above the top level reads the whole map's extremum, kept as one key past the
//!   levels, so that case needs no branch either.
//! - Batched queries ([`NBuffer::query_four_batch`], [`NBuffer::occludes_batch`]; the paper
//!   queries one rectangle per fragment program): the covers of 16 rectangles are computed
//!   at once (vectorized) and their cache lines prefetched one block ahead of the loads. The
//!   results and lookup counts are those of the single queries (tested). A lone query waits
//!   on its four cache misses; a batch keeps many in flight, which is what the §3.1 flat
//!   object list and the §3.2 sprites can use.
//!
//! # Cost
//! Memory: `levels × w × h × 2` bytes (20 MB at 1024² with the default 10 levels, 6 MB at
//! 640×480). Build: one streaming pass per level, bound by memory bandwidth. A query: O(1), at
//! most four lookups; on maps larger than the L2 cache a lone query costs its cache misses, a
//! batched one a fraction of that (its misses overlap).
//! Not worth it when few rectangles are tested per depth map (rasterizing them is cheaper).

use rayon::prelude::*;

use crate::query::PixelRect;
mod kernels;
use crate::RasterError;
use kernels::{Isa, LANES};

/// Which extremum the levels hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Extremum {
    /// Greatest stored value = nearest depth (reversed-Z).
    Max,
    /// Least stored value = farthest depth (reversed-Z): the occlusion-culling variant.
    Min,
}

impl Extremum {
    /// The value of an empty set: `-inf` for [`Extremum::Max`], `+inf` for [`Extremum::Min`].
    #[inline]
    pub fn identity(self) -> f32 {
        match self {
            Self::Max => f32::NEG_INFINITY,
            Self::Min => f32::INFINITY,
        }
    }
    /// What a NaN depth reads as: the variant's worst case (`+inf` for max, `-inf` for min).
    #[inline]
    pub fn unknown(self) -> f32 {
        match self {
            Self::Max => f32::INFINITY,
            Self::Min => f32::NEG_INFINITY,
        }
    }
    /// The key of the empty set: below (max) or above (min) every stored key.
    #[inline(always)]
    fn key_identity(self) -> Key {
        match self {
            Self::Max => 0,
            Self::Min => Key::MAX,
        }
    }
    /// The storage key of a non-NaN depth, rounded in the safe direction: down for min (the
    /// decoded value is never above `depth`), up for max (never below).
    #[inline(always)]
    fn key_of(self, depth: f32) -> Key {
        let o = order_bits(depth);
        match self {
            Self::Min => (o >> 16) as Key,
            Self::Max => (o.saturating_add(0xffff) >> 16) as Key,
        }
    }
    #[inline(always)]
    fn pick(self, a: Key, b: Key) -> Key {
        match self {
            Self::Max => a.max(b),
            Self::Min => a.min(b),
        }
    }
}

/// A stored depth: the upper 16 bits of the depth's order-preserving bit pattern (sign,
/// exponent and 7 bits of mantissa: a relative precision of 2^-7).
pub type Key = u16;

/// The bits of `f` as an unsigned integer that sorts like `f` (NaN excluded).
#[inline(always)]
fn order_bits(f: f32) -> u32 {
    let b = f.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// The depth a key stands for: exact for keys of depths with 7 mantissa bits or fewer; keys
/// at or below that of `-inf` read `-inf`, at or above that of `+inf` read `+inf`.
#[inline]
pub fn decode_key(key: Key) -> f32 {
    if key <= 0x007f {
        f32::NEG_INFINITY
    } else if key >= 0xff80 {
        f32::INFINITY
    } else {
        let o = u32::from(key) << 16;
        f32::from_bits(if o & 0x8000_0000 != 0 { o & 0x7fff_ffff } else { !o })
    }
}

/// The answer of a query: the bound and how many level lookups it took.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Query {
    /// The bound: never below the rectangle's true maximum ([`Extremum::Max`]), never above its
    /// true minimum ([`Extremum::Min`]); [`Extremum::identity`] for an empty rectangle.
    pub depth: f32,
    /// Lookups into the levels (0 for an empty rectangle).
    pub lookups: u32,
}

/// Which of the five covers of Fig. 3 a rectangle takes (or none).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Cover {
    /// Empty or off-screen: no lookup.
    Empty,
    /// A 1×1 rectangle: one lookup at level 0.
    Pixel,
    /// Fig. 3 left: the rectangle covers the four quadrants of its bounding `2^n` square: four
    /// squares of side `2^(n-1)`, one in each corner.
    Quadrants,
    /// Fig. 3 middle, top: two quadrants side by side, taller than a quarter: two squares of
    /// side `2^(n-1)` on the top edge, each looked up twice (four lookups).
    Row2,
    /// Fig. 3 middle, bottom: the same, turned (a column of two on the left edge).
    Column2,
    /// Fig. 3 right, top: two quadrants on less than half their height: four squares of side
    /// `2^(n-2)` in a row on the top edge.
    Row4,
    /// Fig. 3 right, bottom: the same, turned (a column of four on the left edge).
    Column4,
    /// The rectangle needs a level above the ones built: the whole map's extremum.
    Whole,
}

/// Bytes an N-buffer may hold at most (refused above, before allocating).
pub const MAX_NBUFFER_BYTES: usize = 8 << 30;

/// Rows per parallel band of the build.
const BAND_ROWS: usize = 16;

/// An N-buffer over one depth map: `levels()` full-resolution maps, level `i` holding the
/// extremum over the `2^i` square right of and below each pixel.
#[derive(Clone, Debug)]
pub struct NBuffer {
    extremum: Extremum,
    width: u32,
    height: u32,
    level_count: u32,
    /// Levels one after the other, each `width × height`, row-major.
    data: Vec<Key>,
    /// The extremum of the whole map.
    whole: Key,
}

impl NBuffer {
    /// Levels the four-square query can use on a `width × height` map: `⌈log2 max⌉` (at least 1).
    pub fn default_level_count(width: u32, height: u32) -> u32 {
        let side = width.max(height).max(1);
        (side.next_power_of_two().trailing_zeros()).max(1)
    }

    /// Levels for the one-square query over the whole map: `⌈log2 max⌉ + 1`.
    pub fn full_level_count(width: u32, height: u32) -> u32 {
        Self::default_level_count(width, height) + 1
    }

    /// An N-buffer of `extremum` over `depth` (`width × height`, row-major) with
    /// [`NBuffer::default_level_count`] levels, built in parallel on the current rayon pool.
    ///
    /// # Errors
    /// See [`NBuffer::with_levels`].
    pub fn new(extremum: Extremum, depth: &[f32], width: u32, height: u32) -> Result<Self, RasterError> {
        Self::with_levels(extremum, depth, width, height, Self::default_level_count(width, height))
    }

    /// An N-buffer with `level_count` levels (level 0 is the depth map itself; use fewer
    /// levels when only small rectangles are queried, e.g. sprites, §3.2).
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] for a zero size, `depth.len() != width × height`, zero
    /// levels or more than [`NBuffer::full_level_count`]; [`RasterError::OutOfMemory`] above
    /// [`MAX_NBUFFER_BYTES`] or when allocation fails (checked before allocating).
    pub fn with_levels(
        extremum: Extremum,
        depth: &[f32],
        width: u32,
        height: u32,
        level_count: u32,
    ) -> Result<Self, RasterError> {
        let mut nb = Self {
            extremum,
            width: 0,
            height: 0,
            level_count: 0,
            data: Vec::new(),
            whole: extremum.key_identity(),
        };
        nb.rebuild(depth, width, height, level_count)?;
        Ok(nb)
    }

    /// Rebuilds over a new depth map, reusing the allocation when it is large enough.
    ///
    /// # Errors
    /// As [`NBuffer::with_levels`]; on error the N-buffer is left empty (every query answers
    /// the identity).
    pub fn rebuild(&mut self, depth: &[f32], width: u32, height: u32, level_count: u32) -> Result<(), RasterError> {
        self.rebuild_with(Isa::detected(), depth, width, height, level_count)
    }

    /// [`NBuffer::rebuild`] with the row kernels of `isa`.
    fn rebuild_with(
        &mut self,
        isa: Isa,
        depth: &[f32],
        width: u32,
        height: u32,
        level_count: u32,
    ) -> Result<(), RasterError> {
        self.width = 0;
        self.height = 0;
        self.level_count = 0;
        self.whole = self.extremum.key_identity();
        if width == 0 || height == 0 {
            return Err(RasterError::BadConfig(format!(
                "N-buffer of zero size {width}x{height}"
            )));
        }
        let n = width as usize * height as usize;
        if depth.len() != n {
            return Err(RasterError::BadConfig(format!(
                "N-buffer: depth map has {} values, expected {width}x{height} = {n}",
                depth.len()
            )));
        }
        let full = Self::full_level_count(width, height);
        if level_count == 0 || level_count > full {
            return Err(RasterError::BadConfig(format!(
                "N-buffer: {level_count} levels requested for {width}x{height} (1..={full})"
            )));
        }
        let total = n
            .checked_mul(level_count as usize)
            .filter(|&t| t.checked_mul(2).is_some_and(|b| b <= MAX_NBUFFER_BYTES))
            .ok_or(RasterError::OutOfMemory(
                n.saturating_mul(level_count as usize).saturating_mul(2),
            ))?;
        // One key past the levels holds the whole map's extremum: the index every lookup
        // above the top level points to (the query then needs no branch for it).
        if self.data.len() < total + 1 {
            self.data.clear();
            self.data
                .try_reserve_exact(total + 1)
                .map_err(|_| RasterError::OutOfMemory((total + 1) * 2))?;
            occult_core::memory::advise_huge_pages(self.data.as_mut_ptr() as *mut u8, (total + 1) * 2);
            self.data.resize(total + 1, 0);
        }
        self.width = width;
        self.height = height;
        self.level_count = level_count;
        let ext = self.extremum;
        let unknown = ext.key_of(ext.unknown());
        let w = width as usize;
        // Level 0: the depth map, NaN read as the variant's worst case.
        self.data[..n]
            .par_chunks_mut(BAND_ROWS * w)
            .zip(depth.par_chunks(BAND_ROWS * w))
            .for_each(|(dst, src)| {
                for (d, s) in dst.chunks_exact_mut(w).zip(src.chunks_exact(w)) {
                    kernels::keys_row(isa, ext, d, s, unknown);
                }
            });
        for level in 1..level_count {
            self.build_level(isa, level);
        }
        self.set_whole();
        Ok(())
    }

    /// §2: level `level` from level `level - 1`, in parallel bands of rows.
    fn build_level(&mut self, isa: Isa, level: u32) {
        let (w, h) = (self.width as usize, self.height as usize);
        let n = w * h;
        let step = 1usize << (level - 1);
        let ext = self.extremum;
        let (before, rest) = self.data.split_at_mut(level as usize * n);
        let prev = &before[(level as usize - 1) * n..];
        let cur = &mut rest[..n];
        cur.par_chunks_mut(BAND_ROWS * w).enumerate().for_each(|(band, out)| {
            let y0 = band * BAND_ROWS;
            for (r, out_row) in out.chunks_exact_mut(w).enumerate() {
                let y = y0 + r;
                let a = &prev[y * w..(y + 1) * w];
                let b = (y + step < h).then(|| &prev[(y + step) * w..(y + step + 1) * w]);
                kernels::combine(isa, ext, out_row, a, b, step);
            }
        });
    }

    /// Computes the whole map's extremum and stores it past the levels (the key every lookup
    /// above the top level reads).
    fn set_whole(&mut self) {
        self.whole = self.compute_whole();
        let sentinel = self.whole_index();
        self.data[sentinel] = self.whole;
    }

    /// Index of the key past the levels that holds the whole map's extremum.
    #[inline(always)]
    fn whole_index(&self) -> usize {
        self.level_count as usize * self.width as usize * self.height as usize
    }

    /// The extremum of the whole map from the top level (four lookups when the top level's
    /// square is at least half the map, else a scan of the top level at its square's stride).
    fn compute_whole(&self) -> Key {
        let top = self.level_count - 1;
        let s = 1u32 << top;
        let mut acc = self.extremum.key_identity();
        let mut y = 0;
        loop {
            let mut x = 0;
            loop {
                acc = self.extremum.pick(acc, self.at(top, x, y));
                if x + s >= self.width {
                    break;
                }
                x = (x + s).min(self.width - s);
            }
            if y + s >= self.height {
                break;
            }
            y = (y + s).min(self.height - s);
        }
        acc
    }

    /// After the depth map changed inside `rect` (clipped to the map), brings every level up
    /// to date: level `i` changes only at pixels whose square meets `rect`, i.e. `x` in
    /// `[x0 - 2^i + 1, x1)`, and the same in `y` (§4.2's remark). `depth` is the whole new map.
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] when `depth` does not have the map's size.
    pub fn update_region(&mut self, depth: &[f32], rect: PixelRect) -> Result<(), RasterError> {
        let (w, h) = (self.width as usize, self.height as usize);
        if depth.len() != w * h {
            return Err(RasterError::BadConfig(format!(
                "N-buffer update: depth map has {} values, expected {w}x{h}",
                depth.len()
            )));
        }
        let x1 = (rect.x1 as usize).min(w);
        let y1 = (rect.y1 as usize).min(h);
        let (x0, y0) = (rect.x0 as usize, rect.y0 as usize);
        if x0 >= x1 || y0 >= y1 {
            return Ok(());
        }
        let ext = self.extremum;
        let unknown = ext.key_of(ext.unknown());
        for y in y0..y1 {
            for x in x0..x1 {
                let s = depth[y * w + x];
                self.data[y * w + x] = if s.is_nan() { unknown } else { ext.key_of(s) };
            }
        }
        let n = w * h;
        for level in 1..self.level_count as usize {
            let step = 1usize << (level - 1);
            let side = 1usize << level;
            let (lx0, ly0) = ((x0 + 1).saturating_sub(side), (y0 + 1).saturating_sub(side));
            let (before, rest) = self.data.split_at_mut(level * n);
            let prev = &before[(level - 1) * n..];
            let cur = &mut rest[..n];
            for y in ly0..y1 {
                let a = &prev[y * w..(y + 1) * w];
                let out = &mut cur[y * w + lx0..y * w + x1];
                if y + step < h {
                    let b = &prev[(y + step) * w..(y + step + 1) * w];
                    for (k, o) in out.iter_mut().enumerate() {
                        let x = lx0 + k;
                        let mut v = ext.pick(a[x], b[x]);
                        if x + step < w {
                            v = ext.pick(v, ext.pick(a[x + step], b[x + step]));
                        }
                        *o = v;
                    }
                } else {
                    for (k, o) in out.iter_mut().enumerate() {
                        let x = lx0 + k;
                        *o = if x + step < w {
                            ext.pick(a[x], a[x + step])
                        } else {
                            a[x]
                        };
                    }
                }
            }
        }
        self.set_whole();
        Ok(())
    }

    /// The extremum the levels hold.
    #[inline]
    pub fn extremum(&self) -> Extremum {
        self.extremum
    }
    /// Width of every level.
    #[inline]
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height of every level.
    #[inline]
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Levels built (level 0 is the depth map).
    #[inline]
    pub fn level_count(&self) -> u32 {
        self.level_count
    }
    /// The extremum of the whole map.
    #[inline]
    pub fn whole(&self) -> f32 {
        decode_key(self.whole)
    }
    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.data.capacity() * 2
    }
    /// Level `level` as a row-major slice of keys ([`decode_key`] reads them).
    ///
    /// # Panics
    /// If `level >= level_count()`.
    pub fn level(&self, level: u32) -> &[Key] {
        assert!(level < self.level_count, "level {level} of {}", self.level_count);
        let n = self.width as usize * self.height as usize;
        &self.data[level as usize * n..(level as usize + 1) * n]
    }

    #[inline(always)]
    fn at(&self, level: u32, x: u32, y: u32) -> Key {
        let n = self.width as usize * self.height as usize;
        let i = level as usize * n + y as usize * self.width as usize + x as usize;
        debug_assert!(x < self.width && y < self.height && level < self.level_count);
        self.data[i]
    }

    /// Clips `rect` to the map; `None` when nothing is left.
    #[inline(always)]
    fn clip(&self, rect: PixelRect) -> Option<(u32, u32, u32, u32)> {
        let x1 = rect.x1.min(self.width);
        let y1 = rect.y1.min(self.height);
        if rect.x0 >= x1 || rect.y0 >= y1 {
            None
        } else {
            Some((rect.x0, rect.y0, x1, y1))
        }
    }

    /// §2 "Query", first form: one lookup at the smallest level `i` with `2^i ≥ max(Δx, Δy)`,
    /// at the rectangle's first corner.
    pub fn query_one(&self, rect: PixelRect) -> Query {
        let Some((x0, y0, x1, y1)) = self.clip(rect) else {
            return Query {
                depth: self.extremum.identity(),
                lookups: 0,
            };
        };
        let span = (x1 - x0).max(y1 - y0);
        let level = ceil_log2(span);
        let key = if level < self.level_count {
            self.at(level, x0, y0)
        } else {
            self.whole
        };
        Query {
            depth: decode_key(key),
            lookups: 1,
        }
    }

    /// Which cover of Fig. 3 [`NBuffer::query_four`] takes for `rect`.
    pub fn cover(&self, rect: PixelRect) -> Cover {
        match self.clip(rect) {
            None => Cover::Empty,
            Some((x0, y0, x1, y1)) => self.cover_clipped(x1 - x0, y1 - y0),
        }
    }

    #[inline(always)]
    fn cover_clipped(&self, dx: u32, dy: u32) -> Cover {
        let n = ceil_log2(dx.max(dy));
        if n == 0 {
            return Cover::Pixel;
        }
        let half = 1u32 << (n - 1);
        let quarter = half >> 1; // 0 when n == 1: then both sides exceed a quarter
        let cover = if dx > half && dy > half {
            Cover::Quadrants
        } else if dx > half {
            if dy > quarter {
                Cover::Row2
            } else {
                Cover::Row4
            }
        } else if dx > quarter {
            Cover::Column2
        } else {
            Cover::Column4
        };
        let level = match cover {
            Cover::Row4 | Cover::Column4 => n - 2,
            _ => n - 1,
        };
        if level >= self.level_count {
            Cover::Whole
        } else {
            cover
        }
    }

    /// The four lookups of the cover of `rect`, case by case as Fig. 3 draws them: the
    /// reference that [`NBuffer::four_keys`] is tested against.
    #[inline(always)]
    #[cfg_attr(not(test), allow(dead_code))]
    fn cover_points_by_case(&self, rect: PixelRect) -> (Cover, u32, [(u32, u32); 4]) {
        let Some((x0, y0, x1, y1)) = self.clip(rect) else {
            return (Cover::Empty, 0, [(0, 0); 4]);
        };
        let (dx, dy) = (x1 - x0, y1 - y0);
        let cover = self.cover_clipped(dx, dy);
        let n = ceil_log2(dx.max(dy));
        match cover {
            Cover::Empty | Cover::Whole => (cover, 0, [(0, 0); 4]),
            Cover::Pixel => (cover, 0, [(x0, y0); 4]),
            Cover::Quadrants => {
                let s = 1u32 << (n - 1);
                let (xr, yb) = (x1 - s, y1 - s);
                (cover, n - 1, [(x0, y0), (xr, y0), (x0, yb), (xr, yb)])
            }
            // §2: "we chose top" — squares start on the rectangle's top row and may run
            // below it (the side the paper prefers to over-cover).
            Cover::Row2 => {
                let s = 1u32 << (n - 1);
                (cover, n - 1, [(x0, y0), (x1 - s, y0), (x0, y0), (x1 - s, y0)])
            }
            Cover::Column2 => {
                let s = 1u32 << (n - 1);
                (cover, n - 1, [(x0, y0), (x0, y1 - s), (x0, y0), (x0, y1 - s)])
            }
            Cover::Row4 => {
                let q = 1u32 << (n - 2);
                (cover, n - 2, [(x0, y0), (x0 + q, y0), (x0 + 2 * q, y0), (x1 - q, y0)])
            }
            Cover::Column4 => {
                let q = 1u32 << (n - 2);
                (cover, n - 2, [(x0, y0), (x0, y0 + q), (x0, y0 + 2 * q), (x0, y1 - q)])
            }
        }
    }

    /// Where the four keys of the Fig. 3 cover of `rect` are in `data`, and the lookups they
    /// stand for (1 for a pixel or above the top level, 4 otherwise), or `None` when `rect` is
    /// empty. The five cases are selected arithmetically (one cover formula with selects, no
    /// branch per case): the 2×2 corners at level `n - 1` (whose lower pair falls on the upper
    /// one in the middle cases, and which for a pixel all fall on it), or a row / column of
    /// four at level `n - 2`. Above the top level all four point to the whole map's extremum.
    #[inline(always)]
    fn four_indices(&self, rect: PixelRect) -> Option<([usize; 4], u32)> {
        let (x0, y0, x1, y1) = self.clip(rect)?;
        let (dx, dy) = (x1 - x0, y1 - y0);
        let n = ceil_log2(dx.max(dy));
        // Half the side of the bounding square 2^n (n ≤ 32: no shift past the width).
        let half = if n == 0 { 0 } else { 1u32 << (n - 1) };
        let quarter = half >> 1;
        let row4 = dx > half && dy <= quarter;
        let col4 = dy > half && dx <= quarter;
        let level = n.saturating_sub(1) - u32::from(row4 | col4);
        let s = 1usize << level;
        let w = self.width as usize;
        // Offsets of the far column and row of the cover: x1 - s and y1 - s, not before the
        // rectangle's first corner (they are 0 for a row of four, resp. a column).
        let ex = (x1 as usize).saturating_sub(s).max(x0 as usize) - x0 as usize;
        let ey = ((y1 as usize).saturating_sub(s).max(y0 as usize) - y0 as usize) * w;
        // Row of four: x0, x0 + s, x0 + 2s, x1 - s on row y0; column: the same turned;
        // otherwise the corners (x0, y0), (xr, y0), (x0, yb), (xr, yb).
        let four = row4 | col4;
        let unit = if row4 { 1 } else { w };
        let a = if four { s.wrapping_mul(unit) } else { ex };
        let b = if four { (2 * s).wrapping_mul(unit) } else { ey };
        let base = (level as usize)
            .wrapping_mul(w * self.height as usize)
            .wrapping_add(y0 as usize * w + x0 as usize);
        let inside = level < self.level_count;
        let whole = self.whole_index();
        let idx = if inside {
            [
                base,
                base.wrapping_add(a),
                base.wrapping_add(b),
                base.wrapping_add(ex + ey),
            ]
        } else {
            [whole; 4]
        };
        Some((idx, if n == 0 || !inside { 1 } else { 4 }))
    }

    /// The four keys of the Fig. 3 cover of `rect` ([`NBuffer::four_indices`]).
    #[inline(always)]
    fn four_keys(&self, rect: PixelRect) -> Option<([Key; 4], u32)> {
        let (idx, lookups) = self.four_indices(rect)?;
        Some((idx.map(|i| self.data[i]), lookups))
    }

    /// §2 "Query", four-square form (Fig. 3): the extremum over `rect` from four lookups (one
    /// for a single pixel, none for an empty rectangle).
    #[inline]
    pub fn query_four(&self, rect: PixelRect) -> Query {
        let ext = self.extremum;
        match self.four_keys(rect) {
            None => Query {
                depth: ext.identity(),
                lookups: 0,
            },
            Some(([a, b, c, d], lookups)) => Query {
                depth: decode_key(ext.pick(ext.pick(a, b), ext.pick(c, d))),
                lookups,
            },
        }
    }

    /// §3.1 occlusion test on a [`Extremum::Min`] N-buffer: true when every pixel of `rect`
    /// holds a depth strictly nearer than `nearest` (the nearest depth any fragment of the
    /// tested object can have), so nothing of the object can be kept (ties are not hidden: a
    /// tie can win on item id). Returns `(hidden, lookups)`: the four lookups of
    /// [`NBuffer::query_four`]. An empty rectangle is hidden (it draws nothing); a NaN
    /// `nearest` is never hidden. On a [`Extremum::Max`] N-buffer it answers `false` (a max
    /// bound cannot prove occlusion).
    #[inline]
    pub fn occludes(&self, rect: PixelRect, nearest: f32) -> (bool, u32) {
        if self.extremum != Extremum::Min || nearest.is_nan() {
            return (false, 0);
        }
        match self.four_keys(rect) {
            None => (true, 0),
            Some(([a, b, c, d], lookups)) => {
                // nearest < decode(k)  <=>  order_bits(nearest) < k << 16 (keys are truncated
                // bits), so the test never decodes.
                let farthest = a.min(b).min(c.min(d));
                (order_bits(nearest) < u32::from(farthest) << 16, lookups)
            }
        }
    }

    /// The reduced key ([`Extremum::pick`] of the four) and lookup count of every rectangle
    /// of `rects`, `None` for an empty one, handed to `each` in order. The covers of a block of
    /// rectangles are computed together (vectorized, `kernels::cover_block`) and their cache
    /// lines prefetched one block ahead of the loads, so the lookups of many rectangles are in
    /// flight at once (a lone query waits on each).
    #[inline(always)]
    fn batch_keys(&self, rects: &[PixelRect], mut each: impl FnMut(usize, Option<(Key, u32)>)) {
        let ext = self.extremum;
        let whole = self.whole_index();
        let Ok(whole_index) = u32::try_from(whole) else {
            // Indices past u32: one rectangle at a time.
            for (i, &r) in rects.iter().enumerate() {
                each(
                    i,
                    self.four_keys(r)
                        .map(|([a, b, c, d], n)| (ext.pick(ext.pick(a, b), ext.pick(c, d)), n)),
                );
            }
            return;
        };
        let map = kernels::CoverMap {
            width: self.width,
            height: self.height,
            level_count: self.level_count,
            whole_index,
        };
        let isa = Isa::detected();
        let empty_rect = PixelRect {
            x0: 0,
            y0: 0,
            x1: 0,
            y1: 0,
        };
        let block = |start: usize, idx: &mut [[u32; LANES]; 4], lookups: &mut [u32; LANES]| {
            let end = (start + LANES).min(rects.len());
            match rects[start..end].try_into() {
                Ok(rs) => kernels::cover_block(isa, &map, rs, idx, lookups),
                Err(_) => {
                    let mut rs = [empty_rect; LANES];
                    rs[..end - start].copy_from_slice(&rects[start..end]);
                    kernels::cover_block(isa, &map, &rs, idx, lookups);
                }
            }
        };
        // Two blocks: the one being read and the next one, computed and prefetched first.
        let mut idx = [[[0u32; LANES]; 4]; 2];
        let mut lookups = [[0u32; LANES]; 2];
        if !rects.is_empty() {
            block(0, &mut idx[0], &mut lookups[0]);
        }
        let mut start = 0;
        let mut cur = 0;
        while start < rects.len() {
            let end = (start + LANES).min(rects.len());
            let next = cur ^ 1;
            if end < rects.len() {
                block(end, &mut idx[next], &mut lookups[next]);
                for row in &idx[next] {
                    for &i in row {
                        kernels::prefetch(&self.data, i as usize);
                    }
                }
            }
            let (idx, lookups) = (&idx[cur], &lookups[cur]);
            for k in 0..end - start {
                if lookups[k] == 0 {
                    each(start + k, None);
                } else {
                    let a = self.data[idx[0][k] as usize];
                    let b = self.data[idx[1][k] as usize];
                    let c = self.data[idx[2][k] as usize];
                    let d = self.data[idx[3][k] as usize];
                    each(start + k, Some((ext.pick(ext.pick(a, b), ext.pick(c, d)), lookups[k])));
                }
            }
            cur = next;
            start = end;
        }
    }

    /// [`NBuffer::query_four`] of every rectangle of `rects` into `out` (same results), the
    /// lookups of many rectangles overlapped (for callers that test many rectangles against one
    /// N-buffer: the objects of a flat list, §3.1; sprites, §3.2). Returns the lookups made.
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] when `out` is not as long as `rects`.
    pub fn query_four_batch(&self, rects: &[PixelRect], out: &mut [f32]) -> Result<u64, RasterError> {
        if out.len() != rects.len() {
            return Err(RasterError::BadConfig(format!(
                "N-buffer batch query: {} rectangles but {} results",
                rects.len(),
                out.len()
            )));
        }
        let identity = self.extremum.identity();
        let mut lookups = 0u64;
        self.batch_keys(rects, |i, r| {
            out[i] = match r {
                None => identity,
                Some((key, n)) => {
                    lookups += u64::from(n);
                    decode_key(key)
                }
            }
        });
        Ok(lookups)
    }

    /// [`NBuffer::occludes`] of every rectangle of `rects` against the nearest depth of the same
    /// index in `nearest`, into `hidden` (same results), the lookups of many rectangles
    /// overlapped as in [`NBuffer::query_four_batch`]. Returns the lookups made.
    ///
    /// # Errors
    /// [`RasterError::BadConfig`] when `nearest` or `hidden` is not as long as `rects`.
    pub fn occludes_batch(
        &self,
        rects: &[PixelRect],
        nearest: &[f32],
        hidden: &mut [bool],
    ) -> Result<u64, RasterError> {
        if nearest.len() != rects.len() || hidden.len() != rects.len() {
            return Err(RasterError::BadConfig(format!(
                "N-buffer batch occlusion test: {} rectangles, {} depths, {} results",
                rects.len(),
                nearest.len(),
                hidden.len()
            )));
        }
        if self.extremum != Extremum::Min {
            hidden.fill(false);
            return Ok(0);
        }
        let mut lookups = 0u64;
        self.batch_keys(rects, |i, r| {
            let z = nearest[i];
            hidden[i] = match r {
                None => !z.is_nan(),
                Some((key, n)) => {
                    if z.is_nan() {
                        false
                    } else {
                        lookups += u64::from(n);
                        order_bits(z) < u32::from(key) << 16
                    }
                }
            }
        });
        Ok(lookups)
    }

    /// The occlusion test of [`NBuffer::occludes`] with the one-square query: a single
    /// lookup, exact when `rect` is a power-of-two square (§3.2: sprites of power-of-two
    /// sizes need a single depth comparison).
    #[inline]
    pub fn occludes_one(&self, rect: PixelRect, nearest: f32) -> (bool, u32) {
        if self.extremum != Extremum::Min || nearest.is_nan() {
            return (false, 0);
        }
        let Some((x0, y0, x1, y1)) = self.clip(rect) else {
            return (true, 0);
        };
        let level = ceil_log2((x1 - x0).max(y1 - y0));
        let key = if level < self.level_count {
            self.at(level, x0, y0)
        } else {
            self.whole
        };
        (order_bits(nearest) < u32::from(key) << 16, 1)
    }
}

/// `⌈log2 v⌉` for `v ≥ 1`.
#[inline(always)]
fn ceil_log2(v: u32) -> u32 {
    if v <= 1 {
        0
    } else {
        32 - (v - 1).leading_zeros()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn brute(depth: &[f32], w: u32, ext: Extremum, r: PixelRect, h: u32) -> f32 {
        let mut acc = ext.identity();
        for y in r.y0..r.y1.min(h) {
            for x in r.x0..r.x1.min(w) {
                let d = depth[(y * w + x) as usize];
                let d = if d.is_nan() { ext.unknown() } else { d };
                acc = match ext {
                    Extremum::Max => acc.max(d),
                    Extremum::Min => acc.min(d),
                };
            }
        }
        acc
    }

    fn rect(x0: u32, y0: u32, x1: u32, y1: u32) -> PixelRect {
        PixelRect { x0, y0, x1, y1 }
    }

    /// A min N-buffer of random depths, of random size (below 300 × 300) and level count;
    /// with its width, height and level count.
    fn random_min_map(rng: &mut Pcg64) -> (NBuffer, u32, u32, u32) {
        let (w, h) = (rng.random_range(1..300u32), rng.random_range(1..300u32));
        let depth: Vec<f32> = (0..w * h).map(|_| rng.random::<f32>()).collect();
        let levels = rng.random_range(1..=NBuffer::full_level_count(w, h));
        let nb = NBuffer::with_levels(Extremum::Min, &depth, w, h, levels)
            .expect("a random map below 300x300 with at most the full level count builds");
        (nb, w, h, levels)
    }

    #[test]
    fn keys_round_in_the_safe_direction() {
        let mut rng = Pcg64::seed_from_u64(4);
        let special = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e-30,
            3.3e-7,
        ];
        let randoms = (0..100_000)
            .map(|_| f32::from_bits(rng.random::<u32>()))
            .filter(|v| !v.is_nan());
        for v in special.into_iter().chain(randoms) {
            let lo = decode_key(Extremum::Min.key_of(v));
            let hi = decode_key(Extremum::Max.key_of(v));
            assert!(lo <= v && v <= hi, "{v}: {lo} {hi}");
            if v.is_finite() && v.abs() > 1e-30 && v.abs() < 1e30 {
                assert!((hi - lo).abs() <= v.abs() / 64.0, "{v}: {lo} {hi}");
            }
        }
    }

    #[test]
    fn arithmetic_cover_matches_the_five_cases() {
        let mut rng = Pcg64::seed_from_u64(5);
        for _ in 0..20 {
            let (nb, w, h, _) = random_min_map(&mut rng);
            for _ in 0..2000 {
                let (x0, y0) = (rng.random_range(0..w + 4), rng.random_range(0..h + 4));
                let r = rect(x0, y0, x0 + rng.random_range(0..w + 8), y0 + rng.random_range(0..h + 8));
                let (cover, level, p) = nb.cover_points_by_case(r);
                let fast = nb.four_keys(r);
                match cover {
                    Cover::Empty => assert!(fast.is_none()),
                    Cover::Whole => assert_eq!(fast, Some(([nb.whole; 4], 1))),
                    _ => {
                        let (keys, lookups) = fast.expect("a cover that is neither empty nor whole has four keys");
                        let mut want: Vec<Key> = p.iter().map(|&(x, y)| nb.at(level, x, y)).collect();
                        let mut got = keys.to_vec();
                        want.sort_unstable();
                        want.dedup();
                        got.sort_unstable();
                        got.dedup();
                        assert_eq!(got, want, "{w}x{h} {r:?} {cover:?}");
                        assert_eq!(lookups, if cover == Cover::Pixel { 1 } else { 4 });
                    }
                }
            }
        }
    }

    #[test]
    fn level_counts_match_table_1() {
        assert_eq!(NBuffer::default_level_count(256, 256), 8);
        assert_eq!(NBuffer::default_level_count(512, 512), 9);
        assert_eq!(NBuffer::default_level_count(640, 480), 10);
        assert_eq!(NBuffer::default_level_count(1024, 1024), 10);
        assert_eq!(NBuffer::default_level_count(1, 1), 1);
    }

    #[test]
    fn levels_hold_the_square_extremum() {
        let mut rng = Pcg64::seed_from_u64(1);
        for &(w, h) in &[(1u32, 1u32), (7, 5), (13, 31), (64, 64), (33, 17)] {
            let depth: Vec<f32> = (0..w * h).map(|_| rng.random::<f32>()).collect();
            for ext in [Extremum::Max, Extremum::Min] {
                let nb = NBuffer::with_levels(ext, &depth, w, h, NBuffer::full_level_count(w, h))
                    .expect("a map with its full level count builds");
                for l in 0..nb.level_count() {
                    let s = 1 << l;
                    for y in 0..h {
                        for x in 0..w {
                            let want = ext.key_of(brute(&depth, w, ext, rect(x, y, x + s, y + s), h));
                            assert_eq!(nb.level(l)[(y * w + x) as usize], want, "{w}x{h} level {l} at {x},{y}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn queries_are_conservative_on_random_maps() {
        let mut rng = Pcg64::seed_from_u64(2);
        for seed in 0..40 {
            let w = rng.random_range(1..90u32);
            let h = rng.random_range(1..90u32);
            let depth: Vec<f32> = (0..w * h)
                .map(|_| match rng.random_range(0..20) {
                    0 => f32::NAN,
                    1 => 0.0,
                    _ => rng.random::<f32>(),
                })
                .collect();
            for ext in [Extremum::Max, Extremum::Min] {
                let nb = NBuffer::new(ext, &depth, w, h).expect("a map of matching length builds");
                for _ in 0..300 {
                    let x0 = rng.random_range(0..w + 10);
                    let y0 = rng.random_range(0..h + 10);
                    let r = rect(
                        x0,
                        y0,
                        x0 + rng.random_range(0..w + 20),
                        y0 + rng.random_range(0..h + 20),
                    );
                    let truth = brute(&depth, w, ext, r, h);
                    for q in [nb.query_one(r), nb.query_four(r)] {
                        let ok = match ext {
                            Extremum::Max => q.depth >= truth,
                            Extremum::Min => q.depth <= truth,
                        };
                        assert!(ok, "seed {seed} {w}x{h} {ext:?} {r:?}: {} vs {truth}", q.depth);
                        assert!(q.lookups <= 4);
                    }
                    if ext == Extremum::Min {
                        let z: f32 = rng.random();
                        let (hidden, lookups) = nb.occludes(r, z);
                        assert!(!hidden || z < truth, "seed {seed} {r:?}: {z} hidden behind {truth}");
                        assert!(lookups <= 4);
                        let (hidden, lookups) = nb.occludes_one(r, z);
                        assert!(
                            !hidden || z < truth,
                            "seed {seed} {r:?}: {z} hidden behind {truth} (one)"
                        );
                        assert!(lookups <= 1);
                    }
                }
            }
        }
    }

    #[test]
    fn empty_and_offscreen_rects_answer_identity_without_lookups() {
        let nb = NBuffer::new(Extremum::Min, &[0.5; 12], 4, 3).expect("a 4x3 map of 12 depths builds");
        for r in [
            rect(2, 2, 2, 3),
            rect(3, 1, 1, 2),
            rect(4, 0, 9, 3),
            rect(0, 3, 4, 9),
            rect(100, 100, 200, 200),
        ] {
            assert_eq!(
                nb.query_four(r),
                Query {
                    depth: f32::INFINITY,
                    lookups: 0
                }
            );
            assert_eq!(nb.query_one(r).lookups, 0);
            assert_eq!(nb.cover(r), Cover::Empty);
        }
        // Larger than the map: the whole map.
        assert_eq!(nb.query_four(rect(0, 0, u32::MAX, u32::MAX)).depth, 0.5);
        assert_eq!(nb.query_one(rect(0, 0, u32::MAX, u32::MAX)).depth, 0.5);
    }

    #[test]
    fn nan_reads_as_worst_case() {
        let mut depth = vec![0.5f32; 16];
        depth[5] = f32::NAN;
        let max = NBuffer::new(Extremum::Max, &depth, 4, 4).expect("a 4x4 map of 16 depths builds");
        let min = NBuffer::new(Extremum::Min, &depth, 4, 4).expect("a 4x4 map of 16 depths builds");
        assert_eq!(max.query_four(rect(0, 0, 4, 4)).depth, f32::INFINITY);
        assert_eq!(min.query_four(rect(0, 0, 4, 4)).depth, f32::NEG_INFINITY);
        assert_eq!(min.query_four(rect(2, 2, 4, 4)).depth, 0.5);
        assert!(!min.occludes(rect(0, 0, 4, 4), 0.1).0);
        assert!(min.occludes(rect(2, 2, 4, 4), 0.1).0);
        assert!(!min.occludes(rect(2, 2, 4, 4), f32::NAN).0);
    }

    #[test]
    fn five_covers_of_fig_3() {
        let nb = NBuffer::new(Extremum::Min, &vec![0.5; 64 * 64], 64, 64).expect("a 64x64 map builds");
        assert_eq!(nb.cover(rect(0, 0, 1, 1)), Cover::Pixel);
        assert_eq!(nb.cover(rect(3, 3, 23, 20)), Cover::Quadrants);
        assert_eq!(nb.cover(rect(3, 3, 23, 13)), Cover::Row2);
        assert_eq!(nb.cover(rect(3, 3, 13, 23)), Cover::Column2);
        assert_eq!(nb.cover(rect(3, 3, 23, 5)), Cover::Row4);
        assert_eq!(nb.cover(rect(3, 3, 5, 23)), Cover::Column4);
        // A 64-wide rectangle needs level 5 = the top of the default 6 levels.
        assert_eq!(nb.cover(rect(0, 0, 64, 64)), Cover::Quadrants);
        let small = NBuffer::with_levels(Extremum::Min, &vec![0.5; 64 * 64], 64, 64, 3)
            .expect("a 64x64 map with 3 levels builds");
        assert_eq!(small.cover(rect(0, 0, 40, 40)), Cover::Whole);
        assert_eq!(small.query_four(rect(0, 0, 40, 40)).depth, 0.5);
    }

    #[test]
    fn occludes_is_strict_and_counts_lookups() {
        let nb = NBuffer::new(Extremum::Min, &vec![0.5; 32 * 32], 32, 32).expect("a 32x32 map builds");
        assert_eq!(nb.occludes(rect(1, 1, 20, 20), 0.4), (true, 4));
        assert_eq!(nb.occludes(rect(1, 1, 20, 20), 0.5), (false, 4));
        assert_eq!(nb.occludes(rect(1, 1, 20, 11), 0.4), (true, 4));
        assert_eq!(nb.occludes(rect(1, 1, 2, 2), 0.4), (true, 1));
        assert_eq!(nb.occludes_one(rect(1, 1, 17, 17), 0.4), (true, 1));
        assert_eq!(nb.occludes_one(rect(1, 1, 17, 17), 0.5), (false, 1));
        assert_eq!(nb.occludes_one(rect(40, 1, 47, 17), 0.5), (true, 0));
        let max = NBuffer::new(Extremum::Max, &vec![0.5; 32 * 32], 32, 32).expect("a 32x32 map builds");
        assert_eq!(max.occludes(rect(1, 1, 20, 20), 0.1), (false, 0));
    }

    #[test]
    fn region_update_matches_rebuild() {
        let mut rng = Pcg64::seed_from_u64(3);
        for _ in 0..20 {
            let w = rng.random_range(1..70u32);
            let h = rng.random_range(1..70u32);
            let mut depth: Vec<f32> = (0..w * h).map(|_| rng.random::<f32>()).collect();
            for ext in [Extremum::Max, Extremum::Min] {
                let levels = NBuffer::full_level_count(w, h);
                let mut nb =
                    NBuffer::with_levels(ext, &depth, w, h, levels).expect("a map with its full level count builds");
                let x0 = rng.random_range(0..w);
                let y0 = rng.random_range(0..h);
                let r = rect(x0, y0, x0 + rng.random_range(1..10), y0 + rng.random_range(1..10));
                for y in r.y0..r.y1.min(h) {
                    for x in r.x0..r.x1.min(w) {
                        depth[(y * w + x) as usize] = if rng.random_range(0..10) == 0 {
                            f32::NAN
                        } else {
                            rng.random()
                        };
                    }
                }
                nb.update_region(&depth, r).expect("the depths keep the map's size");
                let fresh =
                    NBuffer::with_levels(ext, &depth, w, h, levels).expect("a map with its full level count builds");
                for l in 0..levels {
                    assert_eq!(nb.level(l), fresh.level(l), "{w}x{h} {ext:?} level {l} after {r:?}");
                }
                assert_eq!(nb.whole(), fresh.whole());
            }
        }
    }

    /// Depths with every kind of value the build must convert: NaN, ±0, ±inf, negative,
    /// tiny, huge and random bit patterns.
    fn odd_depths(rng: &mut Pcg64, n: usize) -> Vec<f32> {
        (0..n)
            .map(|_| match rng.random_range(0..12) {
                0 => f32::NAN,
                1 => 0.0,
                2 => -0.0,
                3 => f32::INFINITY,
                4 => f32::NEG_INFINITY,
                5 => -rng.random::<f32>(),
                6 => f32::from_bits(rng.random::<u32>()),
                _ => rng.random::<f32>(),
            })
            .collect()
    }

    #[test]
    fn every_instruction_set_builds_the_same_levels() {
        let mut rng = Pcg64::seed_from_u64(6);
        for &(w, h) in &[
            (1u32, 1u32),
            (1, 9),
            (9, 1),
            (7, 5),
            (33, 17),
            (100, 3),
            (257, 31),
            (64, 64),
        ] {
            let depth = odd_depths(&mut rng, (w * h) as usize);
            for ext in [Extremum::Max, Extremum::Min] {
                let levels = NBuffer::full_level_count(w, h);
                let mut base = NBuffer::with_levels(ext, &[0.0], 1, 1, 1).expect("a 1x1 map builds");
                base.rebuild_with(Isa::Baseline, &depth, w, h, levels)
                    .expect("a map with its full level count rebuilds");
                for isa in Isa::available() {
                    let mut nb = NBuffer::with_levels(ext, &[0.0], 1, 1, 1).expect("a 1x1 map builds");
                    nb.rebuild_with(isa, &depth, w, h, levels)
                        .expect("a map with its full level count rebuilds");
                    for l in 0..levels {
                        assert_eq!(nb.level(l), base.level(l), "{isa:?} {w}x{h} {ext:?} level {l}");
                    }
                    assert_eq!(nb.whole, base.whole);
                }
                // And the baseline's level 0 is the scalar key of each depth.
                for (i, &d) in depth.iter().enumerate() {
                    let want = if d.is_nan() {
                        ext.key_of(ext.unknown())
                    } else {
                        ext.key_of(d)
                    };
                    assert_eq!(base.level(0)[i], want, "{d}");
                }
            }
        }
    }

    fn random_rect(rng: &mut Pcg64, w: u32, h: u32) -> PixelRect {
        match rng.random_range(0..10) {
            0 => rect(0, 0, u32::MAX, u32::MAX),
            1 => {
                let (x, y) = (rng.random_range(0..w + 4), rng.random_range(0..h + 4));
                rect(x, y, x, y + 3)
            }
            2 => {
                let (x1, y1) = (rng.random_range(0..w + 4), rng.random_range(0..h + 4));
                rect(x1 + 5, y1, x1, y1 + 2)
            }
            3 => rect(w, 0, w + 10, h),
            _ => {
                let (x0, y0) = (rng.random_range(0..w + 4), rng.random_range(0..h + 4));
                rect(x0, y0, x0 + rng.random_range(0..w + 8), y0 + rng.random_range(0..h + 8))
            }
        }
    }

    #[test]
    fn vector_covers_equal_the_scalar_cover() {
        let mut rng = Pcg64::seed_from_u64(7);
        for _ in 0..30 {
            let (nb, w, h, levels) = random_min_map(&mut rng);
            let map = kernels::CoverMap {
                width: w,
                height: h,
                level_count: levels,
                whole_index: nb.whole_index() as u32,
            };
            for _ in 0..100 {
                let rects: [PixelRect; LANES] = std::array::from_fn(|_| random_rect(&mut rng, w, h));
                for isa in Isa::available() {
                    let (mut idx, mut lookups) = ([[0u32; LANES]; 4], [0u32; LANES]);
                    kernels::cover_block(isa, &map, &rects, &mut idx, &mut lookups);
                    for (k, &r) in rects.iter().enumerate() {
                        match nb.four_indices(r) {
                            None => assert_eq!(lookups[k], 0, "{isa:?} {w}x{h} {r:?}"),
                            Some((want, n)) => {
                                let got = [0, 1, 2, 3].map(|j| idx[j][k] as usize);
                                assert_eq!((got, lookups[k]), (want, n), "{isa:?} {w}x{h} L{levels} {r:?}");
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn batches_answer_as_single_queries() {
        let mut rng = Pcg64::seed_from_u64(8);
        for _ in 0..30 {
            let (w, h) = (rng.random_range(1..200u32), rng.random_range(1..200u32));
            let depth = odd_depths(&mut rng, (w * h) as usize);
            let levels = rng.random_range(1..=NBuffer::full_level_count(w, h));
            for ext in [Extremum::Max, Extremum::Min] {
                let nb = NBuffer::with_levels(ext, &depth, w, h, levels)
                    .expect("a map with at most the full level count builds");
                let count = [0, 1, 15, 16, 17, 33, 200][rng.random_range(0..7)];
                let rects: Vec<PixelRect> = (0..count).map(|_| random_rect(&mut rng, w, h)).collect();
                let nearest: Vec<f32> = (0..count)
                    .map(|_| {
                        if rng.random_range(0..8) == 0 {
                            f32::NAN
                        } else {
                            rng.random()
                        }
                    })
                    .collect();
                let mut out = vec![0.0; count];
                let lookups = nb
                    .query_four_batch(&rects, &mut out)
                    .expect("rects and outputs of equal length");
                let single: Vec<Query> = rects.iter().map(|&r| nb.query_four(r)).collect();
                let want: Vec<u32> = single.iter().map(|q| q.depth.to_bits()).collect();
                assert_eq!(out.iter().map(|d| d.to_bits()).collect::<Vec<_>>(), want);
                assert_eq!(lookups, single.iter().map(|q| u64::from(q.lookups)).sum::<u64>());
                let mut hidden = vec![true; count];
                let lookups = nb
                    .occludes_batch(&rects, &nearest, &mut hidden)
                    .expect("rects, depths and outputs of equal length");
                let single: Vec<(bool, u32)> = rects.iter().zip(&nearest).map(|(&r, &z)| nb.occludes(r, z)).collect();
                assert_eq!(hidden, single.iter().map(|s| s.0).collect::<Vec<_>>());
                assert_eq!(lookups, single.iter().map(|s| u64::from(s.1)).sum::<u64>());
            }
        }
    }

    #[test]
    fn batches_of_unequal_lengths_are_errors() {
        let nb = NBuffer::new(Extremum::Min, &[0.5; 16], 4, 4).expect("a 4x4 map of 16 depths builds");
        let rects = [rect(0, 0, 2, 2); 3];
        assert!(nb.query_four_batch(&rects, &mut [0.0; 2]).is_err());
        assert!(nb.occludes_batch(&rects, &[0.1; 3], &mut [false; 4]).is_err());
        assert!(nb.occludes_batch(&rects, &[0.1; 2], &mut [false; 3]).is_err());
        let mut hidden = [false; 3];
        assert_eq!(
            nb.occludes_batch(&rects, &[0.1; 3], &mut hidden)
                .expect("rects, depths and outputs of equal length"),
            12
        );
        assert_eq!(hidden, [true; 3]);
    }

    #[test]
    fn bad_sizes_are_errors() {
        assert!(NBuffer::new(Extremum::Min, &[], 0, 4).is_err());
        assert!(NBuffer::new(Extremum::Min, &[0.0; 5], 2, 2).is_err());
        assert!(NBuffer::with_levels(Extremum::Min, &[0.0; 4], 2, 2, 0).is_err());
        assert!(NBuffer::with_levels(Extremum::Min, &[0.0; 4], 2, 2, 3).is_err());
        assert!(NBuffer::with_levels(Extremum::Min, &[0.0; 4], 2, 2, 2).is_ok());
        let mut nb = NBuffer::new(Extremum::Max, &[0.0; 4], 2, 2).expect("a 2x2 map of 4 depths builds");
        assert!(nb.update_region(&[0.0; 3], rect(0, 0, 1, 1)).is_err());
    }
}
