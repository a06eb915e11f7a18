//! §IV, the parallel local z-buffer: the frame of one [`Lzb`] computed by several ranks
//! (processes under MPI, or threads), each holding the whole scene and its octrees.
//!
//! # References
//! Han & Zeiger §IV ("We also implement the parallel version LZB ... due to the communication
//! overhead caused by the broadcast of depth buffer at each rendering frame ..."): the paper
//! says that the near pass's depth buffer is broadcast every frame and that the work is shared
//! with MPI; the rest is ours, chosen so that the frame stays the sequential one:
//! 1. every rank walks the octrees (step 1) and splits them by **rank 0's plane** (step 2;
//!    the plane depends on measured rates, which differ between ranks);
//! 2. rank 0 alone renders `S_near` (step 3) and **broadcasts the depth buffer** (the paper's);
//! 3. every rank finds the unfinished pixels from it (step 4) and casts the rays of **its
//!    share of them**: the pixel list in chunks of [`super::CHUNK`] (8×8 tiles in order),
//!    dealt round-robin, so that the costly regions of the screen spread over all ranks;
//! 4. the ranks' PVLs are **united at rank 0**, which draws them into its frame.
//!
//! The union holds every PVL entry the sequential frame would find for any unfinished pixel
//! (a pixel's rays do not depend on the other pixels', bar §III.D's coherence, which bounds
//! traversal but never drops a leaf a robust hit needs), so rank 0's frame is the sequential
//! renderer's: bit-identical to `zbuffer`.
//!
//! # Deviations
//! - `payoff=off` and `mode=lazy` only: payoff decides per rank from its own clock whether to
//!   give a frame up, which would split the ranks; naive mode shades hits, which are not a
//!   PVL to unite.
//! - The ranks' other frames hold rank 0's near depth only; their statistics count their own
//!   rays (rank 0's its own, plus the PVL it draws).
//! - The paper does not say how it shares the rays; the round-robin deal of tiles is ours.

use occult_core::{Affine3A, ItemId, NodeId, View};
use occult_raster::Frame;

use super::cast::InstanceRec;
use super::{Lzb, Mode};
use crate::{FrameStats, RenderError, Result};

/// What a rank of §IV's parallel LZB exchanges with the others, once per frame each, in this
/// order; implemented over a transport by `occult-mpi`. Every method is collective: each rank
/// calls it, and rank 0's value is the one that counts.
pub trait FrameShare {
    /// This rank, in `0..size()`.
    fn rank(&self) -> usize;
    /// Ranks sharing the frame.
    fn size(&self) -> usize;
    /// Rank 0's partition plane (view distance) on every rank.
    ///
    /// # Errors
    /// [`RenderError::Ranks`] for a transport failure.
    fn plane(&mut self, z_clip: f32) -> Result<f32>;
    /// Rank 0's near depth buffer written into every rank's `frame` (the paper's broadcast).
    ///
    /// # Errors
    /// [`RenderError::Ranks`] for a transport failure.
    fn depth(&mut self, frame: &mut Frame) -> Result<()>;
    /// Every rank's `pvl` (encoded) at rank 0, in rank order, rank 0's own first; `None` on
    /// the other ranks.
    ///
    /// # Errors
    /// [`RenderError::Ranks`] for a transport failure.
    fn pvl(&mut self, pvl: Vec<u8>) -> Result<Option<Vec<Vec<u8>>>>;
}

impl Lzb {
    /// Renders `view` as one rank of §IV's parallel LZB (see the module doc): every rank
    /// calls it with the same view; rank 0's `frame` is then the frame [`crate::Renderer::render`]
    /// would draw, the other ranks' hold rank 0's near depth.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] unless built with `payoff=off` and `mode=lazy`; the
    /// share's errors; as [`crate::Renderer::render`].
    pub fn render_shared(&mut self, view: &View, frame: &mut Frame, share: &mut dyn FrameShare) -> Result<FrameStats> {
        if self.direct.is_some() || self.opts.mode != Mode::Lazy {
            return Err(RenderError::BadParameter(
                "lzb: the parallel local z-buffer (§IV) needs payoff=off and mode=lazy".into(),
            ));
        }
        self.render_frame(view, frame, Some(share))
    }
}

/// Keeps this rank's share of the unfinished pixels: chunks of `chunk` dealt round-robin.
pub(super) fn keep_share(pixels: &mut Vec<u32>, chunk: usize, rank: usize, size: usize) {
    *pixels = pixels
        .chunks(chunk)
        .enumerate()
        .filter(|(k, _)| k % size == rank)
        .flat_map(|(_, c)| c.iter().copied())
        .collect();
}

/// Bytes of a PVL pair `(instance's first item, leaf)` and of an instance record `(first
/// item, node, world_from_object)`.
const PAIR_BYTES: usize = 12;
const REC_BYTES: usize = 8 + 4 + 48;

/// Sends this rank's PVL (`pairs`, and the instances they name in `recs`) to rank 0, which
/// receives the others' into its own. True on rank 0 (which then draws), false elsewhere.
pub(super) fn unite_pvl(
    share: &mut dyn FrameShare,
    pairs: &mut Vec<(ItemId, u32)>,
    recs: &mut std::collections::HashMap<ItemId, InstanceRec, crate::hash::FxBuild>,
) -> Result<bool> {
    let mut bytes = Vec::with_capacity(8 + pairs.len() * PAIR_BYTES + recs.len() * REC_BYTES);
    bytes.extend_from_slice(&(pairs.len() as u64).to_le_bytes());
    for &(item, leaf) in pairs.iter() {
        bytes.extend_from_slice(&item.to_le_bytes());
        bytes.extend_from_slice(&leaf.to_le_bytes());
    }
    for (&item, rec) in recs.iter() {
        bytes.extend_from_slice(&item.to_le_bytes());
        bytes.extend_from_slice(&rec.node.0.to_le_bytes());
        for v in rec.world_from_object.to_cols_array() {
            bytes.extend_from_slice(&v.to_bits().to_le_bytes());
        }
    }
    let Some(all) = share.pvl(bytes)? else {
        return Ok(false);
    };
    for (rank, b) in all.iter().enumerate().skip(1) {
        decode(b, pairs, recs).ok_or_else(|| RenderError::Ranks(format!("rank {rank} sent a malformed PVL")))?;
    }
    Ok(true)
}

fn decode(
    b: &[u8],
    pairs: &mut Vec<(ItemId, u32)>,
    recs: &mut std::collections::HashMap<ItemId, InstanceRec, crate::hash::FxBuild>,
) -> Option<()> {
    let u64_at = |i: usize| Some(u64::from_le_bytes(b.get(i..i + 8)?.try_into().ok()?));
    let u32_at = |i: usize| Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?));
    let n = usize::try_from(u64_at(0)?).ok()?;
    let recs_at = 8usize.checked_add(n.checked_mul(PAIR_BYTES)?)?;
    if recs_at > b.len() || !(b.len() - recs_at).is_multiple_of(REC_BYTES) {
        return None;
    }
    for k in 0..n {
        let at = 8 + k * PAIR_BYTES;
        pairs.push((u64_at(at)?, u32_at(at + 8)?));
    }
    for at in (recs_at..b.len()).step_by(REC_BYTES) {
        let mut cols = [0f32; 12];
        for (j, c) in cols.iter_mut().enumerate() {
            *c = f32::from_bits(u32_at(at + 12 + 4 * j)?);
        }
        recs.insert(
            u64_at(at)?,
            InstanceRec {
                node: NodeId(u32_at(at + 8)?),
                world_from_object: Affine3A::from_cols_array(&cols),
            },
        );
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_cover_every_pixel_once() {
        let pixels: Vec<u32> = (0..1000).collect();
        for size in 1..=5 {
            let mut all: Vec<u32> = (0..size)
                .flat_map(|rank| {
                    let mut p = pixels.clone();
                    keep_share(&mut p, 64, rank, size);
                    p
                })
                .collect();
            all.sort_unstable();
            assert_eq!(all, pixels, "{size} ranks");
        }
        let mut none = Vec::new();
        keep_share(&mut none, 64, 1, 2);
        assert!(none.is_empty());
    }

    #[test]
    fn pvls_round_trip_and_malformed_ones_are_refused() {
        let mut pairs = vec![(5u64, 3u32), (9, 1)];
        let mut recs = std::collections::HashMap::<ItemId, InstanceRec, crate::hash::FxBuild>::default();
        recs.insert(
            5,
            InstanceRec {
                node: NodeId(2),
                world_from_object: Affine3A::from_translation(occult_core::Vec3::new(1.0, -2.0, 0.5)),
            },
        );
        struct Loop(Vec<u8>);
        impl FrameShare for Loop {
            fn rank(&self) -> usize {
                0
            }
            fn size(&self) -> usize {
                2
            }
            fn plane(&mut self, z: f32) -> Result<f32> {
                Ok(z)
            }
            fn depth(&mut self, _: &mut Frame) -> Result<()> {
                Ok(())
            }
            fn pvl(&mut self, pvl: Vec<u8>) -> Result<Option<Vec<Vec<u8>>>> {
                // Rank 1 sends what rank 0 sent.
                Ok(Some(vec![pvl.clone(), std::mem::replace(&mut self.0, pvl)]))
            }
        }
        let mut share = Loop(Vec::new());
        // First round: rank 1's bytes are empty (malformed: no count).
        assert!(unite_pvl(&mut share, &mut pairs, &mut recs).is_err());
        let (mut p2, mut r2) = (vec![], std::collections::HashMap::default());
        assert!(unite_pvl(&mut share, &mut p2, &mut r2).expect("well formed"));
        assert_eq!(p2, pairs);
        assert_eq!(
            r2.get(&5).map(|r| (r.node, r.world_from_object)),
            Some((NodeId(2), recs[&5].world_from_object))
        );
    }
}
