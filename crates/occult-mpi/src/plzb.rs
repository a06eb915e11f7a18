//! §IV's parallel local z-buffer over a [`Comm`]: every rank holds the whole scene and its
//! `lzb` octrees; rank 0 renders the near pass and broadcasts its depth buffer, the ranks cast
//! the rays of their shares of the unfinished pixels, and their PVLs are united at rank 0,
//! which draws them (`occult_render::lzb::shared` holds the algorithm and its references).
//! Rank 0's frame is the sequential `lzb` frame, bit-identical to `zbuffer`.
//!
//! A frame agrees (every rank's outcome so far, [`agree`]) before each of its exchanges and at
//! its end, so that a rank that fails anywhere in a frame (its near pass, its rays, a
//! malformed message, out of memory) ends the frame on every rank with one error naming it,
//! instead of leaving the others waiting in the next exchange.

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Scene, View};
use occult_raster::Frame;
use occult_render::lzb::shared::FrameShare;
use occult_render::lzb::{Lzb, LzbOptions};
use occult_render::{AlgoSpec, FrameStats, RenderError, RenderOptions, Renderer, Result};

use crate::comm::{agree, broadcast, gather, Comm};
use crate::sortlast::{Fault, FaultClock, SortLastConfig};

/// [`FrameShare`] over a [`Comm`], counting the time and bytes of its exchanges.
///
/// Every exchange begins with an agreement ([`agree`]) on whether every rank got there: a rank
/// that failed since the last one (its near pass, its rays, a malformed message) does not
/// come to the exchange but calls the next agreement with its error
/// ([`ParallelLzb::render`]), and every rank returns that error there. No rank waits in an
/// exchange on a rank that failed.
struct CommShare<'a> {
    comm: &'a dyn Comm,
    time: Duration,
    bytes_sent: u64,
    /// Agreements passed this frame.
    agreements: usize,
    /// A failure injected for a test, when it strikes this rank in this frame.
    fault: Option<Fault>,
    /// The frame's failure is settled: an agreement announced it, or the transport failed
    /// (no agreement can follow).
    settled: bool,
}

fn ranks_error(e: crate::CommError) -> RenderError {
    RenderError::Ranks(e.to_string())
}

impl CommShare<'_> {
    /// The next agreement, every rank having got here.
    ///
    /// # Errors
    /// The failure of any rank, agreed; this rank's injected fault (not yet agreed).
    fn checkpoint(&mut self) -> Result<()> {
        if let Some(fault) = self.fault.filter(|f| f.agreement == self.agreements) {
            return Err(fault.error());
        }
        self.agreements += 1;
        self.timed(|c| agree(c, Ok(())))
    }

    /// `f`'s exchange, timed; its errors settle the frame (an agreed failure, or the transport's).
    fn timed<T>(&mut self, f: impl FnOnce(&dyn Comm) -> Result<T, crate::CommError>) -> Result<T> {
        let t = Instant::now();
        let out = f(self.comm).map_err(ranks_error);
        self.time += t.elapsed();
        self.settled |= out.is_err();
        out
    }
}

impl FrameShare for CommShare<'_> {
    fn rank(&self) -> usize {
        self.comm.rank()
    }
    fn size(&self) -> usize {
        self.comm.size()
    }
    fn plane(&mut self, z_clip: f32) -> Result<f32> {
        self.checkpoint()?;
        let bytes = self.timed(|c| broadcast(c, z_clip.to_bits().to_le_bytes().to_vec()))?;
        let bits: [u8; 4] = bytes
            .as_slice()
            .try_into()
            .map_err(|_| RenderError::Ranks("rank 0 sent a malformed plane".into()))?;
        Ok(f32::from_bits(u32::from_le_bytes(bits)))
    }
    fn depth(&mut self, frame: &mut Frame) -> Result<()> {
        self.checkpoint()?;
        let root = self.comm.rank() == 0;
        let mine = if root {
            frame.depth().iter().flat_map(|d| d.to_bits().to_le_bytes()).collect()
        } else {
            Vec::new()
        };
        if root {
            self.bytes_sent += mine.len() as u64;
        }
        let bytes = self.timed(|c| broadcast(c, mine))?;
        if !root {
            let (depth, _) = frame.buffers_mut();
            if bytes.len() != depth.len() * 4 {
                return Err(RenderError::Ranks("rank 0 sent a depth buffer of another size".into()));
            }
            for (d, b) in depth.iter_mut().zip(bytes.chunks_exact(4)) {
                *d = f32::from_bits(u32::from_le_bytes(b.try_into().expect("chunks of 4")));
            }
        }
        Ok(())
    }
    fn pvl(&mut self, pvl: Vec<u8>) -> Result<Option<Vec<Vec<u8>>>> {
        self.checkpoint()?;
        if self.comm.rank() != 0 {
            self.bytes_sent += pvl.len() as u64;
        }
        self.timed(|c| gather(c, &pvl))
    }
}

/// `lzb` as §IV's parallel local z-buffer over the ranks of a [`Comm`] (see the module doc).
pub struct ParallelLzb {
    comm: Arc<dyn Comm>,
    lzb: Lzb,
    replicate: bool,
    faults: FaultClock,
}

impl ParallelLzb {
    /// Builds `lzb` with `spec`'s settings over the whole `scene` on this rank, with
    /// `config`'s `replicate` (every rank ends a frame with rank 0's) and `fault`.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for settings other than `payoff=off`, `mode=lazy` (§IV
    /// needs both; see `occult_render::lzb::shared`); the build's errors.
    pub fn new(
        comm: Arc<dyn Comm>,
        scene: Arc<Scene>,
        options: &RenderOptions,
        spec: &AlgoSpec,
        config: &SortLastConfig,
    ) -> Result<Self> {
        let opts = LzbOptions::from_params(&spec.params)?;
        if opts.payoff {
            return Err(RenderError::BadParameter(
                "lzb: the parallel local z-buffer (§IV) needs payoff=off (each rank's payoff would decide alone)"
                    .into(),
            ));
        }
        Ok(Self {
            comm,
            lzb: Lzb::new(scene, options, &opts)?,
            replicate: config.replicate,
            faults: FaultClock::new(config.fault),
        })
    }

    /// The frame's exchanges, each after an agreement, and a last agreement at its end.
    fn frame(&mut self, view: &View, frame: &mut Frame, share: &mut CommShare<'_>) -> Result<FrameStats> {
        let stats = self.lzb.render_shared(view, frame, share)?;
        if self.replicate {
            share.checkpoint()?;
            let cost = share.timed(|c| crate::composite::replicate(c, frame))?;
            share.bytes_sent += cost.bytes_sent;
            if let Some(defect) = cost.defect {
                return Err(ranks_error(defect));
            }
        }
        share.checkpoint()?;
        Ok(stats)
    }
}

impl Renderer for ParallelLzb {
    fn name(&self) -> &'static str {
        self.lzb.name()
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let start = Instant::now();
        let comm = Arc::clone(&self.comm);
        let fault = self.faults.next_frame(comm.rank());
        let mut share = CommShare {
            comm: comm.as_ref(),
            time: Duration::ZERO,
            bytes_sent: 0,
            agreements: 0,
            fault,
            settled: false,
        };
        let mut stats = match self.frame(view, frame, &mut share) {
            Ok(stats) => stats,
            Err(e) if share.settled => return Err(e),
            // This rank failed alone: the others wait at the next agreement, where it says so.
            Err(e) => {
                return Err(ranks_error(
                    agree(comm.as_ref(), Err(e.to_string()))
                        .err()
                        .unwrap_or_else(|| crate::CommError::Malformed {
                            peer: 0,
                            reason: "an agreement passed a failure over".into(),
                        }),
                ));
            }
        };
        stats.counters.add_all([
            ("mpi_ranks", self.comm.size() as u64),
            ("mpi_comm_us", share.time.as_micros() as u64),
            ("mpi_bytes_sent", share.bytes_sent),
            ("mpi_agreements", share.agreements as u64),
        ]);
        stats.total = start.elapsed();
        Ok(stats)
    }

    fn memory_bytes(&self) -> usize {
        self.lzb.memory_bytes()
    }

    fn is_conservative(&self) -> bool {
        self.lzb.is_conservative()
    }
}
