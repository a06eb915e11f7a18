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
//! Cost per rank and frame, with `n` pixels of `B` = 12 bytes (f32 depth, u64 item):
//! swap sends `n·B·(1 − 1/q)`, gather `n·B/q` (rank 0 receives `n·B·(1 − 1/q)`), the fold
//! `n·B` on the folded ranks; `log2 q + 1` message latencies. [`model`](crate::model) uses it.

use occult_raster::{keep_fragment, Frame};

use crate::comm::{Comm, CommError};

/// Bytes a pixel takes on the wire: f32 depth and u64 item id.
pub const BYTES_PER_PIXEL: usize = 12;

/// What one composite cost this rank.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CompositeCost {
    /// Bytes this rank sent.
    pub bytes_sent: u64,
    /// Bytes this rank received.
    pub bytes_received: u64,
    /// Messages this rank sent.
    pub messages_sent: u64,
}

/// Composites every rank's `frame` into rank 0's (binary swap, then gather; see the module
/// doc). The other ranks' frames are left holding partial composites, unless `replicate`, when
/// every rank ends with the composite.
///
/// # Errors
/// Transport errors; [`CommError::Malformed`] for a message of the wrong length (frames of
/// different sizes on different ranks).
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
            // The lower rank sends first, so that neither waits on a send (see `comm`).
            if rank < partner {
                send_range(comm, partner, frame, give, &mut cost)?;
                receive_range(comm, partner, frame, keep.clone(), true, &mut cost)?;
            } else {
                receive_range(comm, partner, frame, keep.clone(), true, &mut cost)?;
                send_range(comm, partner, frame, give, &mut cost)?;
            }
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
        let more = self::replicate(comm, frame)?;
        cost.bytes_sent += more.bytes_sent;
        cost.bytes_received += more.bytes_received;
        cost.messages_sent += more.messages_sent;
    }
    Ok(cost)
}

/// Rank 0's frame (depth and items) on every rank, along a binary tree.
///
/// # Errors
/// Transport errors; [`CommError::Malformed`] for frames of different sizes.
pub fn replicate(comm: &dyn Comm, frame: &mut Frame) -> Result<CompositeCost, CommError> {
    let (rank, size) = (comm.rank(), comm.size());
    let pixel_count = frame.depth().len();
    let mut cost = CompositeCost::default();
    let bytes = if rank == 0 {
        encode(frame, 0..pixel_count)
    } else {
        Vec::new()
    };
    let bytes = crate::comm::broadcast(comm, bytes)?;
    let sends = tree_sends(rank, size) as u64;
    cost.bytes_sent += bytes.len() as u64 * sends;
    cost.messages_sent += sends;
    if rank != 0 {
        cost.bytes_received += bytes.len() as u64;
        // The broadcast's data comes from rank 0.
        decode_into(0, &bytes, frame, 0..pixel_count, false)?;
    }
    Ok(cost)
}

/// The pixel range rank `rank < q` holds after the swap rounds.
fn finished_range(rank: usize, q: usize, pixel_count: usize) -> std::ops::Range<usize> {
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

fn encode(frame: &Frame, range: std::ops::Range<usize>) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(range.len() * BYTES_PER_PIXEL);
    for d in &frame.depth()[range.clone()] {
        bytes.extend_from_slice(&d.to_bits().to_le_bytes());
    }
    for i in &frame.items()[range] {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    bytes
}

/// Writes (or merges, when `merge`) `bytes`, an encoded `range`, into `frame`.
fn decode_into(
    peer: usize,
    bytes: &[u8],
    frame: &mut Frame,
    range: std::ops::Range<usize>,
    merge: bool,
) -> Result<(), CommError> {
    let n = range.len();
    if bytes.len() != n * BYTES_PER_PIXEL {
        return Err(CommError::Malformed {
            peer,
            reason: format!(
                "{} bytes for {n} pixels (frames of different sizes on different ranks?)",
                bytes.len()
            ),
        });
    }
    let (depth_bytes, item_bytes) = bytes.split_at(n * 4);
    let (depth, items) = frame.buffers_mut();
    let depth = &mut depth[range.clone()];
    let items = &mut items[range];
    for (i, (d, it)) in depth_bytes.chunks_exact(4).zip(item_bytes.chunks_exact(8)).enumerate() {
        let d = f32::from_bits(u32::from_le_bytes(d.try_into().expect("chunks of 4")));
        let it = u64::from_le_bytes(it.try_into().expect("chunks of 8"));
        if merge {
            keep_fragment(&mut depth[i], &mut items[i], d, it);
        } else {
            depth[i] = d;
            items[i] = it;
        }
    }
    Ok(())
}

fn send_range(
    comm: &dyn Comm,
    to: usize,
    frame: &Frame,
    range: std::ops::Range<usize>,
    cost: &mut CompositeCost,
) -> Result<(), CommError> {
    let bytes = encode(frame, range);
    cost.bytes_sent += bytes.len() as u64;
    cost.messages_sent += 1;
    comm.send(to, &bytes)
}

/// Receives `range` from `from` into `frame`: merged by (depth, item id) when `merge`, else
/// copied (a finished range).
fn receive_range(
    comm: &dyn Comm,
    from: usize,
    frame: &mut Frame,
    range: std::ops::Range<usize>,
    merge: bool,
    cost: &mut CompositeCost,
) -> Result<(), CommError> {
    let bytes = comm.recv(from)?;
    cost.bytes_received += bytes.len() as u64;
    decode_into(from, &bytes, frame, range, merge)
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
            composite(c.as_ref(), &mut f, false).map(|_| f)
        });
        let f = out
            .into_iter()
            .next()
            .expect("rank 0")
            .expect("no panic")
            .expect("composites");
        assert!(f.items().iter().all(|&i| i == NO_ITEM));
        let out = run_threads(2, |c| {
            let mut f = Frame::new(4 + c.rank() as u32, 4).expect("small frame");
            composite(c.as_ref(), &mut f, false)
        });
        assert!(out
            .into_iter()
            .any(|r| matches!(r, Ok(Err(CommError::Malformed { .. })))));
    }
}
