//! The frame: depth, item id and color per pixel.

use crate::RasterError;
use occult_core::memory::advise_huge_pages;
use occult_core::{ItemId, NO_ITEM};

/// Depth of a cleared pixel: reversed-Z zero, infinitely far.
pub const CLEAR_DEPTH: f32 = 0.0;

/// Depth of a pixel outside the region a frame is drawn for ([`Frame::region`]): nearer than
/// anything, so that every depth test and occlusion test finds whatever lies there hidden and
/// judges a box by its pixels in the region alone.
pub const BLOCKED_DEPTH: f32 = f32::INFINITY;

/// A `width × height` frame, row-major, row 0 at the top. Depth is reversed-Z `z_ndc`
/// (greater is nearer, [`CLEAR_DEPTH`] when nothing was drawn); item ids name the triangle
/// instance kept at each pixel ([`NO_ITEM`] when none); color is filled by [`crate::shade`].
#[derive(Clone, Debug)]
pub struct Frame {
    width: u32,
    height: u32,
    pub(crate) depth: Vec<f32>,
    pub(crate) items: Vec<ItemId>,
    pub(crate) color: Vec<[u8; 4]>,
    /// True while `color` was written by the renderer for the current depth and items (see
    /// [`Frame::resolved_color_mut`]); [`crate::shade`] then leaves it alone.
    pub(crate) color_resolved: bool,
    /// The pixels drawn into, `[x0, y0, x1, y1)`: the whole frame but for a frame prepared for a
    /// region ([`crate::Rasterizer::clear_region`]), whose other pixels hold [`BLOCKED_DEPTH`].
    region: [u32; 4],
    /// Written by a caller through [`Frame::buffers_mut`] or [`Frame::write_fragment`] since it
    /// was last cleared: rows outside `band` may hold anything.
    foreign: bool,
}

/// Frames are equal when their sizes, buffers and whether their colors were resolved are:
/// the region it was last prepared for is not part of the picture.
impl PartialEq for Frame {
    fn eq(&self, other: &Self) -> bool {
        self.width == other.width
            && self.height == other.height
            && self.depth == other.depth
            && self.items == other.items
            && self.color == other.color
            && self.color_resolved == other.color_resolved
    }
}

impl Frame {
    /// A cleared frame.
    ///
    /// # Errors
    /// [`RasterError::Resolution`] for a zero or oversized resolution (see
    /// [`occult_core::check_resolution`]); [`RasterError::OutOfMemory`] when the buffers
    /// cannot be allocated. The check happens before any allocation.
    pub fn new(width: u32, height: u32) -> Result<Self, RasterError> {
        occult_core::check_resolution(width, height)?;
        let n = width as usize * height as usize;
        let mut depth = Vec::new();
        let mut items = Vec::new();
        let mut color = Vec::new();
        let bytes = n * 16;
        depth
            .try_reserve_exact(n)
            .map_err(|_| RasterError::OutOfMemory(bytes))?;
        items
            .try_reserve_exact(n)
            .map_err(|_| RasterError::OutOfMemory(bytes))?;
        color
            .try_reserve_exact(n)
            .map_err(|_| RasterError::OutOfMemory(bytes))?;
        // A tile of a row-major frame spans 64 rows, each in another 4 KiB page: huge pages
        // spare the scan their walks.
        advise_huge_pages(depth.as_mut_ptr() as *mut u8, n * 4);
        advise_huge_pages(items.as_mut_ptr() as *mut u8, n * 8);
        depth.resize(n, CLEAR_DEPTH);
        items.resize(n, NO_ITEM);
        color.resize(n, [0, 0, 0, 0]);
        Ok(Self {
            width,
            height,
            depth,
            items,
            color,
            color_resolved: false,
            region: [0, 0, width, height],
            foreign: false,
        })
    }

    /// Width in pixels.
    #[inline]
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in pixels.
    #[inline]
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Depth per pixel, row-major.
    #[inline]
    pub fn depth(&self) -> &[f32] {
        &self.depth
    }
    /// Item id per pixel, row-major.
    #[inline]
    pub fn items(&self) -> &[ItemId] {
        &self.items
    }
    /// Color per pixel (RGBA8), row-major; valid after [`crate::shade`].
    #[inline]
    pub fn color(&self) -> &[[u8; 4]] {
        &self.color
    }
    /// Resets depth and items (colors are stale until the next [`crate::shade`]).
    pub fn clear(&mut self) {
        self.color_resolved = false;
        self.depth.fill(CLEAR_DEPTH);
        self.items.fill(NO_ITEM);
        self.region = [0, 0, self.width, self.height];
        self.foreign = false;
    }

    /// The pixels this frame was last prepared for ([`crate::Rasterizer::clear_region`]),
    /// `[x0, y0, x1, y1)`: the whole frame, or a region whose other pixels hold
    /// [`BLOCKED_DEPTH`].
    pub fn region(&self) -> [u32; 4] {
        self.region
    }

    /// Depth and items, for the rasterizer, which writes only the region of the view it draws
    /// ([`Frame::note_drawn`]).
    pub(crate) fn buffers_unmarked(&mut self) -> (&mut [f32], &mut [ItemId]) {
        self.color_resolved = false;
        (&mut self.depth, &mut self.items)
    }

    /// Notes a draw over `region` (`[x0, y0, x1, y1)`): one beyond the region the frame was
    /// prepared for writes pixels that its next preparation must block again.
    pub(crate) fn note_drawn(&mut self, region: [u32; 4]) {
        let r = self.region;
        if region[0] < r[0] || region[1] < r[1] || region[2] > r[2] || region[3] > r[3] {
            self.foreign = true;
        }
    }

    /// The region this frame holds, and whether a caller wrote pixels since it was last
    /// cleared; records the region it is being prepared for, written by no one.
    pub(crate) fn prepare(&mut self, region: [u32; 4]) -> ([u32; 4], bool) {
        let before = (self.region, self.foreign);
        self.region = region;
        self.foreign = false;
        before
    }
    /// Pixels holding an item.
    pub fn covered_pixel_count(&self) -> u64 {
        self.items.iter().filter(|&&i| i != NO_ITEM).count() as u64
    }
    /// The distinct items visible in the frame, sorted: the exactly visible set. Neighbouring
    /// pixels of a row mostly hold the same item, so each run of one item is taken once
    /// before the sort (not every covered pixel's id sorted).
    pub fn visible_items(&self) -> Vec<ItemId> {
        let mut v = Vec::new();
        let mut last = NO_ITEM;
        for &i in &self.items {
            if i != last && i != NO_ITEM {
                v.push(i);
            }
            last = i;
        }
        v.sort_unstable();
        v.dedup();
        v
    }
    /// True when depth (bit for bit) and items are identical; colors follow from items.
    pub fn same_visibility(&self, other: &Frame) -> bool {
        self.width == other.width
            && self.height == other.height
            && self.items == other.items
            && self
                .depth
                .iter()
                .zip(&other.depth)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
    /// Pixels whose item differs from `other`'s (frames of equal size).
    ///
    /// # Panics
    /// If the sizes differ (a programmer error).
    pub fn differing_item_count(&self, other: &Frame) -> u64 {
        assert_eq!(
            (self.width, self.height),
            (other.width, other.height),
            "frame sizes differ"
        );
        self.items.iter().zip(&other.items).filter(|(a, b)| a != b).count() as u64
    }
    /// Peak signal-to-noise ratio of this frame's color against `reference`'s, in dB over RGB;
    /// infinite when identical.
    ///
    /// # Panics
    /// If the sizes differ (a programmer error).
    pub fn color_psnr(&self, reference: &Frame) -> f64 {
        assert_eq!(
            (self.width, self.height),
            (reference.width, reference.height),
            "frame sizes differ"
        );
        let mut sum = 0f64;
        for (a, b) in self.color.iter().zip(&reference.color) {
            for c in 0..3 {
                let d = a[c] as f64 - b[c] as f64;
                sum += d * d;
            }
        }
        let mse = sum / (self.color.len() as f64 * 3.0);
        if mse == 0.0 {
            f64::INFINITY
        } else {
            10.0 * (255.0f64 * 255.0 / mse).log10()
        }
    }
    /// Bytes of the frame's buffers.
    pub fn memory_bytes(&self) -> usize {
        self.depth.len() * 16
    }

    /// Color as an RGBA8 image (after [`crate::shade`]).
    pub fn color_image(&self) -> image::RgbaImage {
        let raw: Vec<u8> = self.color.iter().flatten().copied().collect();
        // The buffer has exactly width * height * 4 bytes.
        image::RgbaImage::from_raw(self.width, self.height, raw).expect("buffer size matches")
    }

    /// Depth visualised as grey levels: near white, far dark, cleared pixels black. Depth is
    /// mapped logarithmically between the frame's nearest and farthest drawn depth.
    pub fn depth_image(&self) -> image::GrayImage {
        let drawn = || self.depth.iter().copied().filter(|&d| d > CLEAR_DEPTH && d.is_finite());
        let lo = drawn().fold(f32::INFINITY, f32::min).max(1e-12);
        let hi = drawn().fold(0.0f32, f32::max).max(lo);
        let (llo, lhi) = (lo.ln(), hi.ln());
        let span = (lhi - llo).max(1e-6);
        let raw = self
            .depth
            .iter()
            .map(|&d| {
                if d > CLEAR_DEPTH && d.is_finite() {
                    (32.0 + 223.0 * ((d.max(lo).ln() - llo) / span)) as u8
                } else {
                    0
                }
            })
            .collect();
        image::GrayImage::from_raw(self.width, self.height, raw).expect("buffer size matches")
    }

    /// Mutable access to depth and items, for renderers that write pixels themselves (point
    /// samples, ray casting) under the same (depth, item) rule as the rasterizer.
    pub fn buffers_mut(&mut self) -> (&mut [f32], &mut [ItemId]) {
        self.foreign = true;
        self.buffers_unmarked()
    }

    /// Colors written by a renderer that resolves them itself (a filtered reconstruction whose
    /// color is not a function of the item ids): marks them resolved, so [`crate::shade`]
    /// keeps them, until depth or items are next written ([`Frame::buffers_mut`],
    /// [`Frame::clear`]).
    pub fn resolved_color_mut(&mut self) -> &mut [[u8; 4]] {
        self.color_resolved = true;
        &mut self.color
    }

    /// True when the renderer resolved the colors ([`Frame::resolved_color_mut`]).
    #[inline]
    pub fn color_resolved(&self) -> bool {
        self.color_resolved
    }

    /// Writes a fragment at pixel `(x, y)` under the frame's rule: it is kept when nearer
    /// (greater depth), or equally near with a smaller item id. Returns whether it was kept.
    #[inline]
    pub fn write_fragment(&mut self, x: u32, y: u32, depth: f32, item: ItemId) -> bool {
        self.foreign = true;
        let i = y as usize * self.width as usize + x as usize;
        keep_fragment(&mut self.depth[i], &mut self.items[i], depth, item)
    }
}

/// DESIGN invariant 1: a pixel keeps the fragment nearest by depth, ties broken by the smaller
/// item id, so the result does not depend on submission order or thread count.
#[inline(always)]
pub fn keep_fragment(stored_depth: &mut f32, stored_item: &mut ItemId, depth: f32, item: ItemId) -> bool {
    if depth > *stored_depth || (depth == *stored_depth && item < *stored_item) {
        *stored_depth = depth;
        *stored_item = item;
        true
    } else {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The visible set: every item a pixel holds, once, sorted, whatever runs and gaps the
    /// rows hold.
    #[test]
    fn visible_items_are_the_distinct_items_sorted() {
        let mut f = Frame::new(7, 3).expect("a 7x3 frame");
        let rows: [ItemId; 21] = [
            5, 5, 5, NO_ITEM, 5, 9, 9, //
            2, 9, 9, 9, NO_ITEM, NO_ITEM, 2, //
            NO_ITEM, 40, 40, 5, 2, 2, 40,
        ];
        f.buffers_mut().1.copy_from_slice(&rows);
        assert_eq!(f.visible_items(), vec![2, 5, 9, 40]);
        f.buffers_mut().1.fill(NO_ITEM);
        assert!(f.visible_items().is_empty());
    }

    #[test]
    fn zero_and_absurd_resolutions_are_errors() {
        assert!(Frame::new(0, 10).is_err());
        assert!(Frame::new(100_000, 100_000).is_err());
        assert!(Frame::new(4, 3).is_ok());
    }

    #[test]
    fn fragment_rule_is_order_independent() {
        let frags = [(0.5f32, 7u64), (0.5, 3), (0.25, 1), (0.5, 9)];
        let mut a = Frame::new(1, 1).expect("a 1x1 frame");
        let mut b = Frame::new(1, 1).expect("a 1x1 frame");
        for &(d, i) in &frags {
            a.write_fragment(0, 0, d, i);
        }
        for &(d, i) in frags.iter().rev() {
            b.write_fragment(0, 0, d, i);
        }
        assert!(a.same_visibility(&b));
        assert_eq!(a.items()[0], 3);
    }
}
