//! Sort-last compositing: every rank holds a whole frame of its part of the scene; the
//! composite keeps, per pixel, the fragment nearest by (depth, item id) — the rasterizer's own
//! rule ([`occult_raster::keep_fragment`]), so that the composite of parts is bit-identical to
//! the frame of the whole scene whatever the split.
//!
//! **Binary swap** (Ma, Painter, Hansen, Krogh 1994), as IceT and ParaView do it:
//! 1. *Fold* (ranks not a power of two): with `q` the largest power of two ≤ `p`, rank `q + i`
//!    sends its whole frame to rank `i`, which merges it, and waits.
//! 2. *Swap*: `log2 q` rounds; in round `k` rank `r` pairs with `r ^ 2^k`, both halve the pixel
//!    range they hold, each sends the half the other keeps and merges the half it receives.
//!    After the rounds rank `r` holds the finished `1/q` of the frame.
//! 3. *Gather*: the finished ranges to rank 0 (and, when asked, the whole frame back to every
//!    rank along a binary tree).
//!
//! **Active pixels only** (IceT's active-pixel encoding, Moreland et al., SC 2011): a range
//! goes on the wire as runs of (empty pixels, active pixels) followed by the active pixels'
//! depths and item ids; an empty pixel (no item, cleared depth) costs nothing to send and
//! nothing to merge, as merging it would change nothing. A rank's part of a split scene covers
//! a compact region of the screen, so most of its frame is empty.
//!
//! Cost per rank and frame, with `n` pixels of `B` = 12 bytes (f32 depth, u64 item), at most
//! (every pixel active): swap sends `n·B·(1 − 1/q)`, gather `n·B/q` (rank 0 receives
//! `n·B·(1 − 1/q)`), the fold `n·B` on the folded ranks; `log2 q + 1` message latencies.
//! [`model`](crate::model) uses it. Each run adds 8 bytes.
//!
//! **Failures.** A message of the wrong layout (frames of different sizes on different ranks)
//! does not stop a rank's part of the exchange: the rank sends and receives every message it
//! would have, and returns the defect in [`CompositeCost::defect`], for the caller to agree
//! on with the other ranks. So no rank waits on a rank that stopped; only the transport's own
//! errors end the exchange at once.

use std::ops::Range;
use std::time::{Duration, Instant};

use occult_core::{ItemId, NO_ITEM};
use occult_raster::{keep_fragment, Frame, CLEAR_DEPTH};

use crate::comm::{Comm, CommError};

/// Bytes an active pixel takes on the wire: f32 depth and u64 item id.
pub const BYTES_PER_PIXEL: usize = 12;

/// Bytes of a run on the wire: its empty then its active pixel counts, u32 each.
pub const BYTES_PER_RUN: usize = 8;

/// What one composite cost this rank, and what went wrong in it short of the transport.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompositeCost {
    /// Bytes this rank sent.
    pub bytes_sent: u64,
    /// Bytes this rank received.
    pub bytes_received: u64,
    /// Messages this rank sent.
    pub messages_sent: u64,
    /// Active pixels this rank sent (the others went as run lengths).
    pub active_pixels_sent: u64,
    /// Time in sends and receives: waiting for the partner to be ready, and the transfer.
    pub wait: Duration,
    /// Time encoding, decoding and merging: the compositing's own work.
    pub work: Duration,
    /// The first message of the wrong layout this rank received (frames of different sizes
    /// on different ranks), found while the exchange went on to its end.
    pub defect: Option<CommError>,
}

impl CompositeCost {
    fn add(&mut self, other: CompositeCost) {
        self.bytes_sent += other.bytes_sent;
        self.bytes_received += other.bytes_received;
        self.messages_sent += other.messages_sent;
        self.active_pixels_sent += other.active_pixels_sent;
        self.wait += other.wait;
        self.work += other.work;
        if self.defect.is_none() {
            self.defect = other.defect;
        }
    }
}

/// Composites every rank's `frame` into rank 0's (binary swap, then gather; see the module
/// doc). The other ranks' frames are left holding partial composites, unless `replicate`, when
/// every rank ends with the composite.
///
/// # Errors
/// Transport errors, which leave the exchange unfinished. A message of the wrong layout is no
/// error here but [`CompositeCost::defect`]: the caller agrees on it.
pub fn composite(comm: &dyn Comm, frame: &mut Frame, replicate: bool) -> Result<CompositeCost, CommError> {
    let (rank, size) = (comm.rank(), comm.size());
    let mut cost = CompositeCost::default();
    if size == 1 {
        return Ok(cost);
    }
    let pixel_count = frame.depth().len();
    let q = 1usize << (usize::BITS - 1 - size.leading_zeros());
    // 1. Fold.
    if rank >= q {
        send_range(comm, rank - q, frame, 0..pixel_count, &mut cost)?;
    } else if rank + q < size {
        receive_range(comm, rank + q, frame, 0..pixel_count, true, &mut cost)?;
    }
    // 2. Swap.
    let mut range = 0..pixel_count;
    if rank < q {
        let mut bit = 1;
        while bit < q {
            let partner = rank ^ bit;
            let mid = range.start + (range.end - range.start) / 2;
            let (keep, give) = if rank & bit == 0 {
                (range.start..mid, mid..range.end)
            } else {
                (mid..range.end, range.start..mid)
            };
            // Both encode, exchange, then merge: neither waits while the other merges. The
            // lower rank sends first, so that neither waits on a send (see `comm`).
            let out = encode_range(frame, give, &mut cost);
            let received = if rank < partner {
                send(comm, partner, &out, &mut cost)?;
                recv(comm, partner, &mut cost)?
            } else {
                let received = recv(comm, partner, &mut cost)?;
                send(comm, partner, &out, &mut cost)?;
                received
            };
            drop(out);
            merge_range(partner, &received, frame, keep.clone(), true, &mut cost);
            range = keep;
            bit <<= 1;
        }
    }
    // 3. Gather.
    if rank == 0 {
        for from in 1..q {
            let r = finished_range(from, q, pixel_count);
            receive_range(comm, from, frame, r, false, &mut cost)?;
        }
    } else if rank < q {
        send_range(comm, 0, frame, range, &mut cost)?;
    }
    if replicate {
        cost.add(self::replicate(comm, frame)?);
    }
    Ok(cost)
}

/// Rank 0's frame (depth and items) on every rank, along a binary tree.
///
/// # Errors
/// Transport errors. A message of the wrong layout (frames of different sizes) is
/// [`CompositeCost::defect`], as in [`composite`].
pub fn replicate(comm: &dyn Comm, frame: &mut Frame) -> Result<CompositeCost, CommError> {
    let (rank, size) = (comm.rank(), comm.size());
    let pixel_count = frame.depth().len();
    let mut cost = CompositeCost::default();
    let t = Instant::now();
    let bytes = if rank == 0 {
        let (bytes, active) = encode(frame, 0..pixel_count);
        cost.active_pixels_sent += active * tree_sends(rank, size) as u64;
        bytes
    } else {
        Vec::new()
    };
    cost.work += t.elapsed();
    let t = Instant::now();
    let bytes = crate::comm::broadcast(comm, bytes)?;
    cost.wait += t.elapsed();
    let sends = tree_sends(rank, size) as u64;
    cost.bytes_sent += bytes.len() as u64 * sends;
    cost.messages_sent += sends;
    if rank != 0 {
        cost.bytes_received += bytes.len() as u64;
        let t = Instant::now();
        // The broadcast's data comes from rank 0.
        if let Err(e) = decode_into(0, &bytes, frame, 0..pixel_count, false) {
            cost.defect = Some(e);
        }
        cost.work += t.elapsed();
    }
    Ok(cost)
}

/// The pixel range rank `rank < q` holds after the swap rounds.
fn finished_range(rank: usize, q: usize, pixel_count: usize) -> Range<usize> {
    let mut range = 0..pixel_count;
    let mut bit = 1;
    while bit < q {
        let mid = range.start + (range.end - range.start) / 2;
        range = if rank & bit == 0 {
            range.start..mid
        } else {
            mid..range.end
        };
        bit <<= 1;
    }
    range
}

/// Messages rank `rank` sends in [`crate::comm::broadcast`] among `size` ranks.
fn tree_sends(rank: usize, size: usize) -> usize {
    let mut step = 1;
    let mut sends = 0;
    while step < size {
        if rank < step && rank + step < size {
            sends += 1;
        }
        step *= 2;
    }
    sends
}

/// Whether a pixel holds nothing: no item and the cleared depth (merging it changes nothing).
#[inline(always)]
fn is_empty(depth: f32, item: ItemId) -> bool {
    item == NO_ITEM && depth.to_bits() == CLEAR_DEPTH.to_bits()
}

/// `range` of `frame` on the wire (see the module doc): the run count (u32), the runs (empty
/// count, active count: u32 each), the active pixels' depths (f32), then their items (u64),
/// little-endian. Returns the bytes and the active pixel count.
fn encode(frame: &Frame, range: Range<usize>) -> (Vec<u8>, u64) {
    let depth = &frame.depth()[range.clone()];
    let items = &frame.items()[range];
    let n = items.len();
    let mut runs: Vec<(u32, u32)> = Vec::new();
    let mut active = 0usize;
    let mut i = 0;
    while i < n {
        let empty_start = i;
        while i < n && is_empty(depth[i], items[i]) {
            i += 1;
        }
        let active_start = i;
        while i < n && !is_empty(depth[i], items[i]) {
            i += 1;
        }
        // Ranges are at most `occult_core::MAX_PIXEL_COUNT` (2^26) pixels: counts fit a u32.
        runs.push(((active_start - empty_start) as u32, (i - active_start) as u32));
        active += i - active_start;
    }
    // Written into a buffer of its final size: no capacity check per value.
    let runs_end = 4 + runs.len() * BYTES_PER_RUN;
    let mut bytes = vec![0u8; runs_end + active * BYTES_PER_PIXEL];
    let (head, pixels) = bytes.split_at_mut(runs_end);
    let (count, run_bytes) = head.split_at_mut(4);
    count.copy_from_slice(&(runs.len() as u32).to_le_bytes());
    for (out, &(e, a)) in run_bytes.chunks_exact_mut(BYTES_PER_RUN).zip(&runs) {
        out[..4].copy_from_slice(&e.to_le_bytes());
        out[4..].copy_from_slice(&a.to_le_bytes());
    }
    let (depth_out, item_out) = pixels.split_at_mut(active * 4);
    let (mut depth_out, mut item_out) = (depth_out.chunks_exact_mut(4), item_out.chunks_exact_mut(8));
    let mut at = 0usize;
    for &(e, a) in &runs {
        at += e as usize;
        let run = at..at + a as usize;
        // The run's values first: zip would take one output chunk too many past the run.
        for (d, out) in depth[run.clone()].iter().zip(depth_out.by_ref()) {
            out.copy_from_slice(&d.to_bits().to_le_bytes());
        }
        for (it, out) in items[run].iter().zip(item_out.by_ref()) {
            out.copy_from_slice(&it.to_le_bytes());
        }
        at += a as usize;
    }
    (bytes, active as u64)
}

/// Writes (or merges, when `merge`) `bytes`, an encoded `range` ([`encode`]), into `frame`:
/// merging skips the empty pixels, writing clears them. Nothing is written unless the whole
/// message is well formed.
fn decode_into(
    peer: usize,
    bytes: &[u8],
    frame: &mut Frame,
    range: Range<usize>,
    merge: bool,
) -> Result<(), CommError> {
    let n = range.len();
    let malformed = |reason: String| CommError::Malformed {
        peer,
        reason: format!("{reason} (frames of different sizes on different ranks?)"),
    };
    let u32_at = |i: usize| -> Option<u32> { Some(u32::from_le_bytes(bytes.get(i..i + 4)?.try_into().ok()?)) };
    let run_count = u32_at(0).ok_or_else(|| malformed(format!("{} bytes, no run count", bytes.len())))? as usize;
    let runs_end = run_count
        .checked_mul(BYTES_PER_RUN)
        .and_then(|r| r.checked_add(4))
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| malformed(format!("{run_count} runs in {} bytes", bytes.len())))?;
    let runs = &bytes[4..runs_end];
    let (mut covered, mut active) = (0usize, 0usize);
    for run in runs.chunks_exact(BYTES_PER_RUN) {
        let (e, a) = run.split_at(4);
        covered += u32::from_le_bytes(e.try_into().expect("4 bytes")) as usize;
        let a = u32::from_le_bytes(a.try_into().expect("4 bytes")) as usize;
        covered += a;
        active += a;
    }
    if covered != n || bytes.len() - runs_end != active * BYTES_PER_PIXEL {
        return Err(malformed(format!(
            "runs of {covered} pixels, {active} active, in {} bytes, for {n} pixels",
            bytes.len()
        )));
    }
    let (depth_bytes, item_bytes) = bytes[runs_end..].split_at(active * 4);
    let mut depth_in = depth_bytes.chunks_exact(4);
    let mut item_in = item_bytes.chunks_exact(8);
    let (depth, items) = frame.buffers_mut();
    let depth = &mut depth[range.clone()];
    let items = &mut items[range];
    let mut at = 0usize;
    for run in runs.chunks_exact(BYTES_PER_RUN) {
        let (e, a) = run.split_at(4);
        let e = u32::from_le_bytes(e.try_into().expect("4 bytes")) as usize;
        let a = u32::from_le_bytes(a.try_into().expect("4 bytes")) as usize;
        if !merge {
            depth[at..at + e].fill(CLEAR_DEPTH);
            items[at..at + e].fill(NO_ITEM);
        }
        at += e;
        let frame_run = depth[at..at + a].iter_mut().zip(&mut items[at..at + a]);
        // The frame's run first: zip would take one input chunk too many past the run.
        for ((d_out, i_out), (d, it)) in frame_run.zip(depth_in.by_ref().zip(item_in.by_ref())) {
            let d = f32::from_bits(u32::from_le_bytes(d.try_into().expect("chunks of 4")));
            let it = u64::from_le_bytes(it.try_into().expect("chunks of 8"));
            if merge {
                keep_fragment(d_out, i_out, d, it);
            } else {
                *d_out = d;
                *i_out = it;
            }
        }
        at += a;
    }
    Ok(())
}

/// `range` of `frame` encoded ([`encode`]), counted in `cost`.
fn encode_range(frame: &Frame, range: Range<usize>, cost: &mut CompositeCost) -> Vec<u8> {
    let t = Instant::now();
    let (bytes, active) = encode(frame, range);
    cost.work += t.elapsed();
    cost.active_pixels_sent += active;
    bytes
}

fn send(comm: &dyn Comm, to: usize, bytes: &[u8], cost: &mut CompositeCost) -> Result<(), CommError> {
    cost.bytes_sent += bytes.len() as u64;
    cost.messages_sent += 1;
    let t = Instant::now();
    let sent = comm.send(to, bytes);
    cost.wait += t.elapsed();
    sent
}

fn recv(comm: &dyn Comm, from: usize, cost: &mut CompositeCost) -> Result<Vec<u8>, CommError> {
    let t = Instant::now();
    let bytes = comm.recv(from)?;
    cost.wait += t.elapsed();
    cost.bytes_received += bytes.len() as u64;
    Ok(bytes)
}

/// Writes `bytes` from `from`, an encoded `range`, into `frame`: merged by (depth, item id)
/// when `merge`, else copied (a finished range). A malformed message is recorded in
/// `cost.defect`.
fn merge_range(
    from: usize,
    bytes: &[u8],
    frame: &mut Frame,
    range: Range<usize>,
    merge: bool,
    cost: &mut CompositeCost,
) {
    let t = Instant::now();
    if let Err(e) = decode_into(from, bytes, frame, range, merge) {
        cost.defect.get_or_insert(e);
    }
    cost.work += t.elapsed();
}

fn send_range(
    comm: &dyn Comm,
    to: usize,
    frame: &Frame,
    range: Range<usize>,
    cost: &mut CompositeCost,
) -> Result<(), CommError> {
    let bytes = encode_range(frame, range, cost);
    send(comm, to, &bytes, cost)
}

fn receive_range(
    comm: &dyn Comm,
    from: usize,
    frame: &mut Frame,
    range: Range<usize>,
    merge: bool,
    cost: &mut CompositeCost,
) -> Result<(), CommError> {
    let bytes = recv(comm, from, cost)?;
    merge_range(from, &bytes, frame, range, merge, cost);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::comm::run_threads;
    use occult_core::NO_ITEM;

    /// Rank `r`'s frame: pixel `i` holds a fragment of depth `f(r, i)` and item `r` or nothing.
    fn frame_of(rank: usize, w: u32, h: u32) -> Frame {
        let mut f = Frame::new(w, h).expect("small frame");
        let (depth, items) = f.buffers_mut();
        for i in 0..depth.len() {
            let v = (i * 7 + rank * 13) % 5;
            if v != 0 {
                depth[i] = v as f32 * 0.1;
                items[i] = (rank as u64 + i as u64) % 3;
            }
        }
        f
    }

    #[test]
    fn composite_equals_the_serial_merge_at_every_size() {
        for size in 1..=7 {
            for replicate in [false, true] {
                let (w, h) = (13, 5);
                let mut expected = frame_of(0, w, h);
                for r in 1..size {
                    let other = frame_of(r, w, h);
                    let (d, it) = expected.buffers_mut();
                    for i in 0..d.len() {
                        keep_fragment(&mut d[i], &mut it[i], other.depth()[i], other.items()[i]);
                    }
                }
                let out = run_threads(size, |c| {
                    let mut f = frame_of(c.rank(), w, h);
                    composite(c.as_ref(), &mut f, replicate).expect("threads stay");
                    f
                });
                for (rank, f) in out.into_iter().enumerate() {
                    let f = f.expect("no rank panics");
                    if rank == 0 || replicate {
                        assert_eq!(f.items(), expected.items(), "{size} ranks, rank {rank}");
                        assert_eq!(f.depth(), expected.depth(), "{size} ranks, rank {rank}");
                    }
                }
            }
        }
    }

    #[test]
    fn empty_frames_composite_to_an_empty_frame_and_sizes_must_match() {
        let out = run_threads(3, |c| {
            let mut f = Frame::new(4, 4).expect("small frame");
            composite(c.as_ref(), &mut f, false).map(|cost| (f, cost))
        });
        let (f, cost) = out
            .into_iter()
            .next()
            .expect("rank 0")
            .expect("no panic")
            .expect("composites");
        assert!(f.items().iter().all(|&i| i == NO_ITEM));
        assert_eq!(cost.active_pixels_sent, 0);
        assert!(cost.defect.is_none());
        // Frames of different sizes: every rank still ends its exchange (none waits on one that
        // stopped), and the ranks that received a message of the wrong layout say so.
        for size in [2, 3, 4, 5] {
            let out = run_threads(size, |c| {
                let mut f = Frame::new(4 + u32::from(c.rank() == 1), 4).expect("small frame");
                composite(c.as_ref(), &mut f, true)
            });
            let costs: Vec<CompositeCost> = out
                .into_iter()
                .map(|r| r.expect("no panic").expect("the transport holds"))
                .collect();
            assert!(
                costs
                    .iter()
                    .any(|c| matches!(c.defect, Some(CommError::Malformed { .. }))),
                "{size} ranks"
            );
        }
    }

    /// Decodes what `encode` made of `range` of `src` into a copy of `dst`.
    fn round_trip(src: &Frame, dst: &Frame, range: std::ops::Range<usize>, merge: bool) -> Frame {
        let (bytes, active) = encode(src, range.clone());
        let covered = range
            .clone()
            .filter(|&i| !is_empty(src.depth()[i], src.items()[i]))
            .count();
        assert_eq!(active, covered as u64);
        let mut out = dst.clone();
        decode_into(1, &bytes, &mut out, range, merge).expect("well formed");
        out
    }

    #[test]
    fn active_pixel_encoding_round_trips_empty_full_and_mixed_ranges() {
        let (w, h) = (13, 5);
        let empty = Frame::new(w, h).expect("small frame");
        let mut full = Frame::new(w, h).expect("small frame");
        {
            let (d, it) = full.buffers_mut();
            for i in 0..d.len() {
                d[i] = 0.5;
                it[i] = i as u64;
            }
        }
        let n = (w * h) as usize;
        for src in [&empty, &full, &frame_of(0, w, h), &frame_of(3, w, h)] {
            for range in [0..n, 0..0, 3..4, 7..n, 0..n / 2] {
                // Copying writes the range exactly, empty pixels cleared.
                let copied = round_trip(src, &full, range.clone(), false);
                for i in 0..n {
                    let from = if range.contains(&i) { src } else { &full };
                    assert_eq!(copied.items()[i], from.items()[i], "pixel {i} of {range:?}");
                    assert_eq!(copied.depth()[i].to_bits(), from.depth()[i].to_bits());
                }
                // Merging equals the rule pixel by pixel.
                let base = frame_of(1, w, h);
                let merged = round_trip(src, &base, range.clone(), true);
                for i in 0..n {
                    let (mut d, mut it) = (base.depth()[i], base.items()[i]);
                    if range.contains(&i) {
                        keep_fragment(&mut d, &mut it, src.depth()[i], src.items()[i]);
                    }
                    assert_eq!((merged.depth()[i].to_bits(), merged.items()[i]), (d.to_bits(), it));
                }
            }
        }
        // An empty range costs its run count only; a full one a run and its pixels.
        assert_eq!(encode(&empty, 0..n).0.len(), 4 + BYTES_PER_RUN);
        assert_eq!(encode(&full, 0..n).0.len(), 4 + BYTES_PER_RUN + n * BYTES_PER_PIXEL);
    }

    #[test]
    fn malformed_messages_write_nothing() {
        let src = frame_of(2, 8, 4);
        let (bytes, _) = encode(&src, 0..32);
        let clean = frame_of(0, 8, 4);
        for bad in [
            Vec::new(),
            bytes[..3].to_vec(),
            bytes[..bytes.len() - 1].to_vec(),
            [bytes.as_slice(), &[0]].concat(),
            // A run count far beyond the message.
            [&u32::MAX.to_le_bytes()[..], &bytes[4..]].concat(),
        ] {
            let mut f = clean.clone();
            assert!(matches!(
                decode_into(1, &bad, &mut f, 0..32, true),
                Err(CommError::Malformed { peer: 1, .. })
            ));
            assert_eq!(f, clean, "nothing written");
        }
        // The right bytes for another range length.
        let mut f = clean.clone();
        assert!(decode_into(1, &bytes, &mut f, 0..31, false).is_err());
        assert_eq!(f, clean);
    }
}
