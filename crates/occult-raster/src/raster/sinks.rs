//! Where set-up triangles go: the tile bins of the binned strategy, or the scan at once (the
//! direct path of one thread and of each sort-last worker), over the whole frame or over one
//! thread's bands of rows (the banded strategy).

use super::project::Viewport;
use super::scan::{prefetch, scan_small, scan_triangle, FrameTarget, SmallCover};
use super::setup::{setup_range, TriSetup, TriStream};
use super::RasterMode;
use std::ops::Range;

/// Reusable per-chunk storage.
#[derive(Default)]
pub(super) struct ChunkBins {
    pub(super) records: Vec<TriSetup>,
    pub(super) bins: Vec<Vec<u32>>,
    pub(super) rasterized: u64,
}

/// An empty pixel box.
pub(super) const EMPTY_RECT: [u32; 4] = [u32::MAX, u32::MAX, 0, 0];

/// The smallest inclusive pixel box holding boxes `a` and `b` (either may be empty, as
/// [`EMPTY_RECT`]).
#[inline(always)]
pub(super) fn union_rect(a: [u32; 4], b: [u32; 4]) -> [u32; 4] {
    [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])]
}

/// The body of [`super::dispatch::draw_direct`], compiled once per instruction set.
///
/// # Safety
/// No other thread may access `target` during the call.
#[inline(always)]
pub(super) unsafe fn draw_direct<const AVX2: bool>(
    vp: &Viewport,
    stream: &TriStream<'_>,
    range: Range<usize>,
    target: &FrameTarget<'_>,
    mode: RasterMode,
) -> (u64, u64, [u32; 4]) {
    // The view's region: the whole frame but for a band (`View::with_region`).
    let rect = vp.region;
    let mut sink = DirectSink::<AVX2> {
        target,
        rect,
        mode,
        rasterized: 0,
        written: 0,
        dirty: EMPTY_RECT,
    };
    setup_range::<AVX2>(vp, stream, range, &mut sink);
    (sink.rasterized, sink.written, sink.dirty)
}

/// Where set-up triangles go: bins for the tile pass, or straight to the scan.
pub(super) trait SetupSink {
    fn push(&mut self, vp: &Viewport, t: TriSetup);
    /// Whether [`Self::push_small`] uses the cover it is given: the 8-lane setup derives edge
    /// functions and masks only for sinks that do.
    const TAKES_EDGES: bool = false;
    /// [`Self::push`] for a triangle whose box the small scan takes, with its edge functions
    /// or, for a tiny box, its mask of covered centres already derived (by the 8-lane setup).
    #[inline(always)]
    fn push_small(&mut self, vp: &Viewport, t: TriSetup, _cover: SmallCover) {
        self.push(vp, t);
    }
    /// `n` triangles the 8-lane setup found to cover no pixel centre of a box of at most
    /// [`TINY`] × [`TINY`] pixels (only sinks that take edge functions get them): they count
    /// as set up; scanning them would write nothing.
    fn count_uncovered(&mut self, n: u32);
    /// Whether the 8-lane setup counts the lanes it hands over, a batch at a time, by
    /// [`Self::count_lanes`]: [`Self::push_lane`] and [`Self::push_small`] then count nothing
    /// (the pieces of a clipped lane still come through [`Self::push`], and count there).
    const COUNTS_LANES: bool = false;
    /// `n` lanes of a batch are about to be handed over (scanned), all within the inclusive
    /// pixel box `bounds` ([`EMPTY_RECT`] when `n` is 0); only called where `COUNTS_LANES`.
    #[inline(always)]
    fn count_lanes(&mut self, _n: u32, _bounds: [u32; 4]) {}
    /// [`Self::push`] for a lane of the 8-lane setup that the small scan does not take.
    #[inline(always)]
    fn push_lane(&mut self, vp: &Viewport, t: TriSetup) {
        self.push(vp, t);
    }
    /// `n` of the triangles pushed were further pieces of one that clipping cut: a triangle
    /// counts once as rasterized, however many pieces it was cut into.
    fn uncount(&mut self, n: u32);
    /// A hint: a triangle whose box starts at pixel `(x, y)` (and covers row `y + 1` if
    /// `two_rows`) is being set up, and a sink that scans at once may start fetching those
    /// pixels. The 8-lane setup hints all eight lanes, a lane without a triangle as (0, 0), so
    /// it must have no effect beyond the fetch.
    #[inline(always)]
    fn will_touch(&mut self, _x: u32, _y: u32, _two_rows: bool) {}
}

impl SetupSink for ChunkBins {
    #[inline(always)]
    fn count_uncovered(&mut self, n: u32) {
        self.rasterized += n as u64;
    }

    fn uncount(&mut self, n: u32) {
        self.rasterized -= n as u64;
    }

    #[inline(always)]
    fn push(&mut self, vp: &Viewport, t: TriSetup) {
        self.rasterized += 1;
        let r = self.records.len() as u32;
        let sh = vp.tile_shift;
        let (tx0, tx1, ty0, ty1) = (
            t.px0 as u32 >> sh,
            t.px1 as u32 >> sh,
            t.py0 as u32 >> sh,
            t.py1 as u32 >> sh,
        );
        self.records.push(t);
        if tx0 == tx1 && ty0 == ty1 {
            self.bins[(ty0 * vp.tiles_x + tx0) as usize].push(r);
            return;
        }
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                self.bins[(ty * vp.tiles_x + tx) as usize].push(r);
            }
        }
    }
}

/// Fetches the pixel `(x, y)` where a triangle's box starts, and the one below when
/// `two_rows` ([`SetupSink::will_touch`]): the rest of the setup (area, depth plane) overlaps
/// with the fetch of pixels the scan is about to test, first touches of the frame being the
/// direct scan's main stall.
#[inline(always)]
fn prefetch_box_start(target: &FrameTarget<'_>, x: u32, y: u32, two_rows: bool) {
    let i = y as usize * target.width + x as usize;
    prefetch(target, i);
    // Without a branch (it mispredicts on tiny triangles): the first row again when the box
    // has one.
    prefetch(target, i + if two_rows { target.width } else { 0 });
}

/// Scans each triangle as soon as it is set up, over the whole frame: the single-threaded path,
/// where binning would only add work. Same scan, same results.
pub(super) struct DirectSink<'a, const AVX2: bool> {
    pub(super) target: &'a FrameTarget<'a>,
    pub(super) rect: [u32; 4],
    pub(super) mode: RasterMode,
    pub(super) rasterized: u64,
    pub(super) written: u64,
    /// Inclusive pixel box of the triangles that wrote a fragment (empty while
    /// `dirty[0] > dirty[2]`): every pixel written is in it.
    pub(super) dirty: [u32; 4],
}

impl<const AVX2: bool> DirectSink<'_, AVX2> {
    /// Counts `written` fragments of triangle `t`, growing the box of what was written by its
    /// box when there are any.
    #[inline(always)]
    fn wrote(&mut self, t: &TriSetup, written: u64) {
        count_written(&mut self.written, &mut self.dirty, t, written);
    }
}

/// Adds `written` fragments of triangle `t` to `count`, and `t`'s box to `dirty` (the box of
/// what was written) when there are any.
#[inline(always)]
fn count_written(count: &mut u64, dirty: &mut [u32; 4], t: &TriSetup, written: u64) {
    if written > 0 {
        *count += written;
        *dirty = union_rect(*dirty, [t.px0, t.py0, t.px1, t.py1].map(u32::from));
    }
}

impl<const AVX2: bool> SetupSink for DirectSink<'_, AVX2> {
    #[inline(always)]
    fn will_touch(&mut self, x: u32, y: u32, two_rows: bool) {
        prefetch_box_start(self.target, x, y, two_rows);
    }

    #[inline(always)]
    fn push(&mut self, vp: &Viewport, t: TriSetup) {
        self.rasterized += 1;
        self.push_lane(vp, t);
    }

    #[inline(always)]
    fn push_lane(&mut self, vp: &Viewport, t: TriSetup) {
        let r = self.rect;
        if u32::from(t.px1) < r[0] || u32::from(t.px0) > r[2] || u32::from(t.py1) < r[1] || u32::from(t.py0) > r[3] {
            return; // wholly outside a band's region
        }
        // SAFETY: a DirectSink is only made by `draw_direct`, whose caller guarantees that
        // no other thread touches the frame during the draw.
        let written = unsafe { scan_triangle::<AVX2>(vp, &t, self.rect, self.target, self.mode) };
        self.wrote(&t, written);
    }

    const TAKES_EDGES: bool = true;

    // Per batch in lanes, where counting each triangle was a load, compare and store of the
    // box's four sides per triangle.
    const COUNTS_LANES: bool = true;

    #[inline(always)]
    fn count_lanes(&mut self, n: u32, _bounds: [u32; 4]) {
        self.rasterized += n as u64;
    }

    #[inline(always)]
    fn count_uncovered(&mut self, n: u32) {
        // Counted like any other; nothing drawn, so the box of what was written stays.
        self.rasterized += n as u64;
    }

    fn uncount(&mut self, n: u32) {
        self.rasterized -= n as u64;
    }

    #[inline(always)]
    fn push_small(&mut self, vp: &Viewport, t: TriSetup, cover: SmallCover) {
        // Counted with its batch (`count_lanes`). Unless the view is a band whose region cuts
        // the box, the direct sink's rectangle holds the box: `scan_triangle` would scan the
        // box itself, small, from these edge functions, or from the mask that the 8-lane setup
        // formed from them.
        let rect = [t.px0 as u32, t.py0 as u32, t.px1 as u32, t.py1 as u32];
        let r = self.rect;
        if rect[0] < r[0] || rect[1] < r[1] || rect[2] > r[2] || rect[3] > r[3] {
            return self.push_lane(vp, t);
        }
        // SAFETY: as in `push`.
        let written = unsafe { scan_small::<AVX2>(vp, &t, rect, cover, self.target, self.mode) };
        self.wrote(&t, written);
    }
}

/// Rows in a band of the banded strategy (a power of two): worker `k` of `n` scans the bands
/// `k, k + n, …` of the frame, so that each gets a share of every part of the screen.
pub(super) const BAND_SHIFT: u32 = 5;

/// The body of [`super::dispatch::draw_banded`], compiled once per instruction set: sets up
/// every triangle of `range` and scans the rows of bands `band, band + bands, …` (of
/// `1 << BAND_SHIFT` rows) only; returns (triangles rasterized, fragments written, the
/// inclusive box of the triangles that wrote any).
///
/// # Safety
/// No other thread may access the rows of those bands in `target` during the call.
#[inline(always)]
pub(super) unsafe fn draw_banded<const AVX2: bool>(
    vp: &Viewport,
    stream: &TriStream<'_>,
    range: Range<usize>,
    target: &FrameTarget<'_>,
    mode: RasterMode,
    band: u32,
    bands: u32,
) -> (u64, u64, [u32; 4]) {
    let mut sink = BandSink::<AVX2> {
        target,
        mode,
        own: band,
        stride: bands,
        last: [vp.width - 1, vp.height - 1],
        rasterized: 0,
        written: 0,
        dirty: EMPTY_RECT,
    };
    setup_range::<AVX2>(vp, stream, range, &mut sink);
    (sink.rasterized, sink.written, sink.dirty)
}

/// Scans each triangle as soon as it is set up, over one worker's bands of rows: every worker
/// sets up every triangle (the setup is repeated, the fill shared), and writes rows no other
/// worker writes, in stream order, so frames and counts are the direct path's.
pub(super) struct BandSink<'a, const AVX2: bool> {
    target: &'a FrameTarget<'a>,
    mode: RasterMode,
    /// This worker's first band, and the workers: its bands are `own, own + stride, …`.
    own: u32,
    stride: u32,
    /// The frame's last column and row.
    last: [u32; 2],
    rasterized: u64,
    written: u64,
    /// As [`DirectSink`]'s: the box of the triangles that wrote a fragment in these bands.
    dirty: [u32; 4],
}

impl<const AVX2: bool> BandSink<'_, AVX2> {
    #[inline(always)]
    fn mine(&self, band: u32) -> bool {
        band % self.stride == self.own
    }

    /// As [`DirectSink`]'s.
    #[inline(always)]
    fn wrote(&mut self, t: &TriSetup, written: u64) {
        count_written(&mut self.written, &mut self.dirty, t, written);
    }

    /// Scans `t` over this worker's bands that its box meets.
    #[inline(always)]
    fn scan_bands(&mut self, vp: &Viewport, t: &TriSetup) {
        let (first, last) = (t.py0 as u32 >> BAND_SHIFT, t.py1 as u32 >> BAND_SHIFT);
        let mut band = first + (self.own + self.stride - first % self.stride) % self.stride;
        while band <= last {
            let top = band << BAND_SHIFT;
            let rect = [0, top, self.last[0], (top + (1 << BAND_SHIFT) - 1).min(self.last[1])];
            // SAFETY: the rows of this worker's bands are its own (`draw_banded`'s caller).
            let written = unsafe { scan_triangle::<AVX2>(vp, t, rect, self.target, self.mode) };
            self.wrote(t, written);
            band += self.stride;
        }
    }
}

impl<const AVX2: bool> SetupSink for BandSink<'_, AVX2> {
    #[inline(always)]
    fn will_touch(&mut self, x: u32, y: u32, two_rows: bool) {
        if self.mine(y >> BAND_SHIFT) {
            prefetch_box_start(self.target, x, y, two_rows);
        }
    }

    #[inline(always)]
    fn push(&mut self, vp: &Viewport, t: TriSetup) {
        self.rasterized += 1;
        self.scan_bands(vp, &t);
    }

    #[inline(always)]
    fn push_lane(&mut self, vp: &Viewport, t: TriSetup) {
        self.scan_bands(vp, &t);
    }

    const TAKES_EDGES: bool = true;
    const COUNTS_LANES: bool = true;

    #[inline(always)]
    fn count_lanes(&mut self, n: u32, _bounds: [u32; 4]) {
        self.rasterized += n as u64;
    }

    #[inline(always)]
    fn count_uncovered(&mut self, n: u32) {
        self.rasterized += n as u64;
    }

    fn uncount(&mut self, n: u32) {
        self.rasterized -= n as u64;
    }

    #[inline(always)]
    fn push_small(&mut self, vp: &Viewport, t: TriSetup, cover: SmallCover) {
        let (first, last) = (t.py0 as u32 >> BAND_SHIFT, t.py1 as u32 >> BAND_SHIFT);
        if first == last {
            if self.mine(first) {
                // As the direct sink: the box, in one of this worker's bands, is the rectangle.
                let rect = [t.px0 as u32, t.py0 as u32, t.px1 as u32, t.py1 as u32];
                // SAFETY: the box's rows are this worker's.
                let written = unsafe { scan_small::<AVX2>(vp, &t, rect, cover, self.target, self.mode) };
                self.wrote(&t, written);
            }
        } else {
            // Across bands: scanned again from its setup in each of this worker's.
            self.scan_bands(vp, &t);
        }
    }
}
