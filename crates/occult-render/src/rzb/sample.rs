//! Sample generation (§5.2, §5.3.3, §7.3) and per-pixel / splatting reconstruction (§4.1,
//! §4.2).

use occult_core::glam::Mat3A;
use occult_core::{Instance, ItemId, Mat4, NodeKind, Scene, Vec3};
use occult_raster::keep_fragment;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::cache::CachedSample;
use super::select::Job;
use super::structure::Structure;

/// Longest instance chain (the scene's nesting limit, 64 nodes).
const MAX_CHAIN: usize = 64;

/// Where samples are written: depth and item buffers of a `width × height` frame.
pub struct Target<'f> {
    /// Depth (reversed-Z, greater is nearer).
    pub depth: &'f mut [f32],
    /// Items.
    pub items: &'f mut [ItemId],
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// Per-thread counts.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleCounts {
    /// Samples generated (drawn from the distribution lists).
    pub generated: u64,
    /// Of which rejected as back-facing (§5.3.3).
    pub backfacing: u64,
    /// Samples projected into the frame (inside the view).
    pub drawn: u64,
}

/// What every sample of a frame shares.
pub struct Sampler<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Its structures.
    pub structures: &'a [Structure],
    /// Splat side `d`.
    pub splat: u32,
    /// Reject back-facing samples (§5.3.3).
    pub backface: bool,
    /// Eye in world space.
    pub eye: Vec3,
    /// Depth of the far plane (fragments with smaller depth are dropped).
    pub far_depth: f32,
    /// Renderer seed.
    pub seed: u64,
}

/// SplitMix64 finaliser: decorrelates the per-box seeds.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The generator of a box: a function of the seed and the box alone, so a frame does not depend
/// on the order boxes are processed in or on the thread count.
pub fn box_rng(seed: u64, job: &Job) -> Pcg64Mcg {
    let h =
        mix(seed
            ^ mix(job.structure as u64 ^ mix(job.base ^ mix(((job.range.start as u64) << 32) | job.range.end as u64))));
    Pcg64Mcg::seed_from_u64(h)
}

/// The generator of piece `piece` of a box's samples.
pub fn piece_rng(seed: u64, job: &Job, piece: u64) -> Pcg64Mcg {
    let h =
        mix(seed
            ^ mix(job.structure as u64 ^ mix(job.base ^ mix(((job.range.start as u64) << 32) | job.range.end as u64))));
    Pcg64Mcg::seed_from_u64(mix(h ^ mix(piece.wrapping_add(0x9e37_79b9_7f4a_7c15))))
}

/// `cof(m)`: maps a normal `e1 × e2` to `(m e1) × (m e2)`, for any linear map.
#[inline]
fn cofactor(m: &Mat3A) -> Mat3A {
    Mat3A::from_cols(
        m.y_axis.cross(m.z_axis),
        m.z_axis.cross(m.x_axis),
        m.x_axis.cross(m.y_axis),
    )
}

/// Number of samples to draw for an expectation `n`: `floor(n)` plus one with probability
/// `frac(n)`, so the expected total is exact (§4.1.1 "a · ln v").
#[inline]
pub fn sample_count(n: f64, rng: &mut Pcg64Mcg) -> u64 {
    let f = n.floor();
    f as u64 + (rng.random::<f64>() < n - f) as u64
}

impl Sampler<'_> {
    /// §5.2 and §7.3: a random point of list positions `range` of `structure`, with probability
    /// proportional to area, descending through instance entries (each choosing in the child's
    /// whole list). Returns the point and the (unnormalised, winding) normal in the structure's
    /// space, and the item id relative to the structure instance's first.
    #[inline]
    pub fn point(&self, structure: u32, range: std::ops::Range<u32>, rng: &mut Pcg64Mcg) -> (Vec3, Vec3, u64) {
        let mut chain: [Option<&Instance>; MAX_CHAIN] = [None; MAX_CHAIN];
        let mut depth = 0;
        let mut sid = structure as usize;
        let mut range = range;
        let mut item = 0u64;
        let (mut p, mut n) = loop {
            let st = &self.structures[sid];
            let pos = st.octree.pick(range, rng.random::<f64>());
            let e = st.octree.entries()[pos as usize] as usize;
            let node = self.scene.node(occult_core::NodeId(sid as u32));
            match node.kind() {
                NodeKind::Mesh(m) => {
                    let [a, b, c] = m.triangle_positions(e);
                    let (mut r1, mut r2) = (rng.random::<f32>(), rng.random::<f32>());
                    if r1 + r2 > 1.0 {
                        r1 = 1.0 - r1;
                        r2 = 1.0 - r2;
                    }
                    item += e as u64;
                    break (a + (b - a) * r1 + (c - a) * r2, (b - a).cross(c - a));
                }
                NodeKind::Group(g) => {
                    let inst = &g[e];
                    item += node.item_offset(e);
                    chain[depth] = Some(inst);
                    depth += 1;
                    sid = inst.child.index();
                    range = 0..self.structures[sid].octree.entries().len() as u32;
                }
            }
        };
        for inst in chain[..depth].iter().rev().flatten() {
            p = inst.parent_from_child.transform_point3(p);
            if self.backface {
                n = cofactor(&inst.parent_from_child.matrix3) * n;
            }
        }
        (p, n, item)
    }

    /// Draws `job`'s samples, freshly generated, into `out`.
    pub fn draw_job(&self, job: &Job, count: u64, rng: &mut Pcg64Mcg, out: &mut Target<'_>, counts: &mut SampleCounts) {
        // Back faces are tested in the structure's space: the eye taken there, the sign of the
        // placement's determinant restoring the winding (§5.3.3).
        let eye = job.world_from_structure.inverse().transform_point3(self.eye);
        let sign = job.world_from_structure.matrix3.determinant().signum();
        for _ in 0..count {
            let (p, n, item) = self.point(job.structure, job.range.clone(), rng);
            counts.generated += 1;
            if self.backface && sign * n.dot(eye - p) <= 0.0 {
                counts.backfacing += 1;
                continue;
            }
            self.splat(&job.clip_from_structure, p, job.base + item, out, counts);
        }
    }

    /// Draws cached samples (already quantized) of a box placed by `clip_from_structure`.
    pub fn draw_cached(
        &self,
        clip_from_structure: &Mat4,
        base: ItemId,
        samples: &[CachedSample],
        out: &mut Target<'_>,
        counts: &mut SampleCounts,
    ) {
        for s in samples {
            self.splat(clip_from_structure, s.position, base + s.item, out, counts);
        }
    }

    /// §4.1/§4.2: projects `p` and writes a `d × d` splat of its depth and item under the frame's
    /// (depth, item) rule.
    #[inline]
    fn splat(
        &self,
        clip_from_structure: &Mat4,
        p: Vec3,
        item: ItemId,
        out: &mut Target<'_>,
        counts: &mut SampleCounts,
    ) {
        let c = *clip_from_structure * p.extend(1.0);
        // Reversed-Z: depth = near / w ≤ 1 in front of the near plane.
        if !(c.w > 0.0) || c.z > c.w || c.x.abs() > c.w || c.y.abs() > c.w {
            return;
        }
        let inv_w = 1.0 / c.w;
        let depth = c.z * inv_w;
        if depth < self.far_depth {
            return;
        }
        let sx = (c.x * inv_w * 0.5 + 0.5) * out.width as f32;
        let sy = (0.5 - c.y * inv_w * 0.5) * out.height as f32;
        let px = (sx as u32).min(out.width - 1);
        let py = (sy as u32).min(out.height - 1);
        counts.drawn += 1;
        if self.splat == 1 {
            let i = (py * out.width + px) as usize;
            keep_fragment(&mut out.depth[i], &mut out.items[i], depth, item);
            return;
        }
        let d = self.splat;
        let x0 = px.saturating_sub((d - 1) / 2);
        let y0 = py.saturating_sub((d - 1) / 2);
        let x1 = (x0 + d).min(out.width);
        let y1 = (y0 + d).min(out.height);
        for y in y0..y1 {
            let row = (y * out.width) as usize;
            for x in x0..x1 {
                let i = row + x as usize;
                keep_fragment(&mut out.depth[i], &mut out.items[i], depth, item);
            }
        }
    }
}
