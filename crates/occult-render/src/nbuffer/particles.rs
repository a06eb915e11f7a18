//! Particle culling with an N-buffer (Décoret 2005 §3.2, §4.3).
//!
//! A particle is a point with a sprite size in pixels; it is drawn as a screen-aligned square
//! sprite (two triangles through the rasterizer, at the particle's depth), like a point
//! sprite. Before drawing, each sprite is tested against an N-buffer (min variant: farthest
//! depth) of the scene's depth buffer in constant time: one lookup when its side is a power of
//! two (the one-square query covers it exactly), four (Fig. 3 cover) otherwise, all of those in
//! one batched call ([`NBuffer::occludes_batch`]: their lookups overlap). Only the first
//! `⌈log2 max size⌉ + 1` levels are built (§3.2: "only the first few levels").
//!
//! Culling never changes the frame ([`draw_particles`] with and without an N-buffer gives
//! bit-identical frames): the N-buffer is built from depth drawn before the sprites and depth
//! only grows nearer as sprites are drawn.
//!
//! # Deviations
//! - A sprite covers the whole pixels `[X, X + size) × [Y, Y + size)` where `X, Y` are the
//!   integer pixel corner nearest to the projected centre minus `size / 2` (as point sprites
//!   cover pixel squares). Its edges then lie on pixel boundaries, half a pixel from every
//!   pixel centre, so the rasterizer's snapping cannot change which pixels it covers and its
//!   pixel rectangle is known exactly.
//! - Sprites are culled on the CPU (the paper did it in a vertex shader); sprites reaching the
//!   near plane or beyond the far plane are dropped, as the rasterizer would drop them.

use std::time::{Duration, Instant};

use occult_core::{Aabb, ItemId, Mat4, Mesh, Vec3, View};
use occult_raster::{Draw, DrawTriangles, Frame, NBuffer, PixelRect, RasterCounts, RasterMode, Rasterizer};

use crate::{RenderError, Result};

/// Most particles a system holds (each becomes two triangles of four vertices per frame).
pub const MAX_PARTICLES: usize = 1 << 25;
/// Largest sprite side in pixels.
pub const MAX_SPRITE_SIZE: u32 = 64;

/// Particles: world positions and sprite sides in pixels.
#[derive(Clone, Debug, Default)]
pub struct Particles {
    /// World positions.
    pub positions: Vec<Vec3>,
    /// Sprite sides in pixels, 1..=[`MAX_SPRITE_SIZE`].
    pub sizes: Vec<u8>,
}

impl Particles {
    /// `count` particles scattered uniformly in the lower `fill` (0..=1) of `bounds` (so
    /// among the buildings of a `city` or the trees of a `forest`), with sprite sides drawn
    /// uniformly from 1..=`max_size`, or from the powers of two up to it when `power_of_two`.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a count above [`MAX_PARTICLES`], a size outside
    /// 1..=[`MAX_SPRITE_SIZE`], `fill` outside (0, 1] or empty bounds.
    pub fn scatter(
        bounds: &Aabb,
        count: usize,
        max_size: u32,
        power_of_two: bool,
        fill: f32,
        seed: u64,
    ) -> Result<Self> {
        if count > MAX_PARTICLES {
            return Err(RenderError::BadParameter(format!(
                "particles: {count} particles, more than {MAX_PARTICLES}"
            )));
        }
        if !(1..=MAX_SPRITE_SIZE).contains(&max_size) {
            return Err(RenderError::BadParameter(format!(
                "particles: sprite size {max_size} is not in 1..={MAX_SPRITE_SIZE}"
            )));
        }
        if !(fill > 0.0 && fill <= 1.0) {
            return Err(RenderError::BadParameter(format!(
                "particles: fill {fill} is not in (0, 1]"
            )));
        }
        if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
            return Err(RenderError::BadParameter(
                "particles: the scene has no finite bounds".into(),
            ));
        }
        let mut rng = SplitMix64(seed);
        let lo = bounds.min;
        let hi = Vec3::new(bounds.max.x, lo.y + (bounds.max.y - lo.y) * fill, bounds.max.z);
        let pow_max = 31 - max_size.leading_zeros(); // log2 of the largest power of two <= max_size
        let mut positions = Vec::with_capacity(count);
        let mut sizes = Vec::with_capacity(count);
        for _ in 0..count {
            let t = Vec3::new(rng.unit(), rng.unit(), rng.unit());
            positions.push(lo + (hi - lo) * t);
            sizes.push(if power_of_two {
                1u8 << rng.below(pow_max + 1)
            } else {
                (1 + rng.below(max_size)) as u8
            });
        }
        Ok(Self { positions, sizes })
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    /// Levels an N-buffer needs to test these sprites with the one-square query.
    pub fn levels_needed(&self) -> u32 {
        let max = self.sizes.iter().copied().max().unwrap_or(1).max(1) as u32;
        max.next_power_of_two().trailing_zeros() + 1
    }
}

/// What [`draw_particles`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParticleCounts {
    /// Sprites in front of the camera, inside the far plane and on screen.
    pub sprites_in_view: u64,
    /// Sprites culled by the N-buffer.
    pub sprites_culled: u64,
    /// N-buffer lookups.
    pub lookups: u64,
    /// Sprites tested with a single lookup (power-of-two sides).
    pub single_lookup_tests: u64,
    /// Time of the N-buffer tests (zero without culling).
    pub cull_time: Duration,
    /// The rasterizer's counts for the sprites drawn.
    pub raster: RasterCounts,
}

/// Draws `particles` as sprites into `frame` (which holds the scene already), with item ids
/// `first_item + 2 i` and `+ 1` for particle `i`'s two triangles. With `cull`, each sprite is
/// first tested against that N-buffer (min variant, built from `frame`'s depth before the
/// sprites) and skipped when hidden; the frame is the same either way. `batched` tests the
/// four-lookup sprites in one [`NBuffer::occludes_batch`] call (the default of the CLI), or
/// one [`NBuffer::occludes`] call each (ablation: same answers, slower).
///
/// # Errors
/// [`RenderError::BadParameter`] when the N-buffer's size differs from the frame's, or when
/// the sprites' mesh cannot be built.
pub fn draw_particles(
    raster: &mut Rasterizer,
    view: &View,
    frame: &mut Frame,
    particles: &Particles,
    first_item: ItemId,
    cull: Option<&NBuffer>,
    batched: bool,
) -> Result<ParticleCounts> {
    if let Some(nb) = cull {
        let frame_size = (frame.width(), frame.height());
        crate::check_same_size("particles", "N-buffer", (nb.width(), nb.height()), "frame", frame_size)?;
    }
    let (w, h) = (frame.width() as f32, frame.height() as f32);
    let clip_from_world = view.clip_from_object(&occult_core::Affine3A::IDENTITY);
    let far_depth = view.far_depth();
    let mut counts = ParticleCounts::default();
    // Pass 1: the sprites in view, their pixel squares and depths.
    let mut sprites: Vec<Sprite> = Vec::new();
    for (i, (&p, &size)) in particles.positions.iter().zip(&particles.sizes).enumerate() {
        let c = clip_from_world * p.extend(1.0);
        // In front of the near plane, not beyond the far plane, finite.
        if !(c.is_finite() && c.w > 0.0 && c.z <= c.w) {
            continue;
        }
        let depth = c.z / c.w;
        if depth < far_depth {
            continue;
        }
        let size = u32::from(size.max(1));
        let cx = (c.x / c.w * 0.5 + 0.5) * w;
        let cy = (0.5 - c.y / c.w * 0.5) * h;
        let x0 = (cx - size as f32 * 0.5).round();
        let y0 = (cy - size as f32 * 0.5).round();
        let (x1, y1) = (x0 + size as f32, y0 + size as f32);
        if x1 <= 0.0 || y1 <= 0.0 || x0 >= w || y0 >= h {
            continue;
        }
        sprites.push(Sprite {
            index: i as u32,
            corner: [x0, y0],
            size,
            depth,
            hidden: false,
        });
    }
    counts.sprites_in_view = sprites.len() as u64;
    if let Some(nb) = cull {
        let t = Instant::now();
        cull_sprites(nb, &mut sprites, (w, h), batched, &mut counts)?;
        counts.cull_time = t.elapsed();
    }
    // Pass 2: the survivors' squares, in particle order.
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut items = Vec::new();
    for sprite in sprites.iter().filter(|s| !s.hidden) {
        let ([x0, y0], size, depth) = (sprite.corner, sprite.size as f32, sprite.depth);
        let (x1, y1) = (x0 + size, y0 + size);
        // The sprite in NDC (w = 1), counter-clockwise with y up.
        let ndc = |x: f32, y: f32| Vec3::new(x / w * 2.0 - 1.0, 1.0 - y / h * 2.0, depth);
        let base = positions.len() as u32;
        positions.extend([ndc(x0, y1), ndc(x1, y1), ndc(x1, y0), ndc(x0, y0)]);
        triangles.push([base, base + 1, base + 2]);
        triangles.push([base, base + 2, base + 3]);
        items.push(sprite.index as usize);
    }
    if triangles.is_empty() {
        return Ok(counts);
    }
    let mesh = Mesh::new(positions, triangles).map_err(|e| RenderError::BadParameter(format!("particles: {e}")))?;
    // One draw per run of consecutive particles keeps item ids `first_item + 2 i` (+1).
    let mut draws = Vec::new();
    let mut k = 0;
    while k < items.len() {
        let mut end = k + 1;
        while end < items.len() && items[end] == items[end - 1] + 1 {
            end += 1;
        }
        draws.push(Draw {
            mesh: &mesh,
            triangles: DrawTriangles::Range(2 * k as u32..2 * end as u32),
            clip_from_object: Mat4::IDENTITY,
            first_item: first_item + 2 * items[k] as u64 - 2 * k as u64,
        });
        k = end;
    }
    counts.raster = raster.draw(view, frame, &draws, RasterMode::Full);
    Ok(counts)
}

/// A sprite in view: its particle, pixel corner, side and depth, and whether it was culled.
struct Sprite {
    index: u32,
    corner: [f32; 2],
    size: u32,
    depth: f32,
    hidden: bool,
}

/// Sprites tested per [`NBuffer::occludes_batch`] call: enough to keep many lookups in
/// flight, few enough that the rectangles stay in L1 and no large buffer is allocated (fresh
/// pages cost more than the tests; measured).
const BATCH: usize = 1024;

/// §3.2: tests every sprite of `sprites` against `nb` (a `w × h` min N-buffer), marking the
/// hidden ones. A power-of-two sprite wholly on screen is one square of the N-buffer: a single
/// lookup ([`NBuffer::occludes_one`]). The others (any side, or clipped by the screen edge:
/// smaller rectangles) take the four-square cover, [`BATCH`] at a time in one
/// [`NBuffer::occludes_batch`] call when `batched` (same answers as one call each; their
/// lookups overlap).
fn cull_sprites(
    nb: &NBuffer,
    sprites: &mut [Sprite],
    (w, h): (f32, f32),
    batched: bool,
    counts: &mut ParticleCounts,
) -> Result<()> {
    let mut rects = Vec::with_capacity(BATCH);
    let mut nearest = Vec::with_capacity(BATCH);
    let mut four = Vec::with_capacity(BATCH);
    let mut hidden = vec![false; BATCH];
    let mut flush =
        |rects: &mut Vec<PixelRect>, nearest: &mut Vec<f32>, four: &mut Vec<u32>, sprites: &mut [Sprite]| {
            let hidden = &mut hidden[..rects.len()];
            let lookups = nb.occludes_batch(rects, nearest, hidden)?;
            for (&k, &hidden) in four.iter().zip(hidden.iter()) {
                sprites[k as usize].hidden = hidden;
            }
            rects.clear();
            nearest.clear();
            four.clear();
            Ok::<u64, RenderError>(lookups)
        };
    for k in 0..sprites.len() {
        let s = &mut sprites[k];
        let [x0, y0] = s.corner;
        let (x1, y1) = (x0 + s.size as f32, y0 + s.size as f32);
        let rect = PixelRect {
            x0: x0.max(0.0) as u32,
            y0: y0.max(0.0) as u32,
            x1: x1.min(w) as u32,
            y1: y1.min(h) as u32,
        };
        let whole_on_screen = rect.x1 - rect.x0 == s.size && rect.y1 - rect.y0 == s.size;
        if s.size.is_power_of_two() && whole_on_screen {
            counts.single_lookup_tests += 1;
            let (hidden, n) = nb.occludes_one(rect, s.depth);
            counts.lookups += u64::from(n);
            s.hidden = hidden;
        } else if !batched {
            let (hidden, n) = nb.occludes(rect, s.depth);
            counts.lookups += u64::from(n);
            s.hidden = hidden;
        } else {
            rects.push(rect);
            nearest.push(s.depth);
            four.push(k as u32);
            if rects.len() == BATCH {
                counts.lookups += flush(&mut rects, &mut nearest, &mut four, sprites)?;
            }
        }
    }
    counts.lookups += flush(&mut rects, &mut nearest, &mut four, sprites)?;
    counts.sprites_culled = sprites.iter().filter(|s| s.hidden).count() as u64;
    Ok(())
}

/// SplitMix64 (Steele et al. 2014): a small seeded generator, enough to scatter particles.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in 0..n (n >= 1).
    fn below(&mut self, n: u32) -> u32 {
        (((self.next() >> 32) * u64::from(n)) >> 32) as u32
    }
}
