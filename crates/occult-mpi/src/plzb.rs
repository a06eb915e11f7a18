//! §IV's parallel local z-buffer over a [`Comm`]: every rank holds the whole scene and its
//! `lzb` octrees; rank 0 renders the near pass and broadcasts its depth buffer, the ranks cast
//! the rays of their shares of the unfinished pixels, and their PVLs are united at rank 0,
//! which draws them (`occult_render::lzb::shared` holds the algorithm and its references).
//! Rank 0's frame is the sequential `lzb` frame, bit-identical to `zbuffer`.

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Scene, View};
use occult_raster::Frame;
use occult_render::lzb::shared::FrameShare;
use occult_render::lzb::{Lzb, LzbOptions};
use occult_render::{AlgoSpec, FrameStats, RenderError, RenderOptions, Renderer, Result};

use crate::comm::{broadcast, gather, Comm};

/// [`FrameShare`] over a [`Comm`], counting the time and bytes of its exchanges.
struct CommShare<'a> {
    comm: &'a dyn Comm,
    time: Duration,
    bytes_sent: u64,
}

fn ranks_error(e: crate::CommError) -> RenderError {
    RenderError::Ranks(e.to_string())
}

impl CommShare<'_> {
    fn timed<T>(&mut self, f: impl FnOnce(&dyn Comm) -> Result<T, crate::CommError>) -> Result<T> {
        let t = Instant::now();
        let out = f(self.comm).map_err(ranks_error);
        self.time += t.elapsed();
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
        let bytes = self.timed(|c| broadcast(c, z_clip.to_bits().to_le_bytes().to_vec()))?;
        let bits: [u8; 4] = bytes
            .as_slice()
            .try_into()
            .map_err(|_| RenderError::Ranks("rank 0 sent a malformed plane".into()))?;
        Ok(f32::from_bits(u32::from_le_bytes(bits)))
    }
    fn depth(&mut self, frame: &mut Frame) -> Result<()> {
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
}

impl ParallelLzb {
    /// Builds `lzb` with `spec`'s settings over the whole `scene` on this rank.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for settings other than `payoff=off`, `mode=lazy` (§IV
    /// needs both; see `occult_render::lzb::shared`); the build's errors.
    /// `replicate`: every rank ends a frame with rank 0's (as
    /// [`crate::SortLastConfig::replicate`]).
    pub fn new(
        comm: Arc<dyn Comm>,
        scene: Arc<Scene>,
        options: &RenderOptions,
        spec: &AlgoSpec,
        replicate: bool,
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
            replicate,
        })
    }
}

impl Renderer for ParallelLzb {
    fn name(&self) -> &'static str {
        self.lzb.name()
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let start = Instant::now();
        let mut share = CommShare {
            comm: self.comm.as_ref(),
            time: Duration::ZERO,
            bytes_sent: 0,
        };
        let mut stats = self.lzb.render_shared(view, frame, &mut share)?;
        if self.replicate {
            let t = Instant::now();
            let cost = crate::composite::replicate(self.comm.as_ref(), frame).map_err(ranks_error)?;
            share.time += t.elapsed();
            share.bytes_sent += cost.bytes_sent;
        }
        stats.counters.add_all([
            ("mpi_ranks", self.comm.size() as u64),
            ("mpi_comm_us", share.time.as_micros() as u64),
            ("mpi_bytes_sent", share.bytes_sent),
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
