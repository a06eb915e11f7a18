//! Sort-last rendering of any renderer: each rank renders its part of the scene
//! ([`crate::partition`]) with the renderer asked for, and the frames are composited by
//! (depth, item id) ([`crate::composite`]) into rank 0's frame, which is then bit-identical to
//! the whole scene's `zbuffer` frame for every conservative renderer.
//!
//! [`sort_last_options`] turns a [`Comm`] into [`RenderOptions`] whose
//! [`RenderOptions::build_around`] hook builds every renderer so: the commands (`compare`,
//! `walk`, `render`) run unchanged, one process per rank, under `mpirun`.
//!
//! A frame, on every rank: render the part; [`agree`] on whether every rank succeeded (so a
//! failed rank ends the run with one error, never a hang); composite (which every rank takes to
//! its end even when a message was malformed); gather the ranks' times, counts and compositing
//! outcomes to rank 0, which announces the first failure, or reports them as counters
//! (`mpi_*`, below). Every rank so returns from every frame with the same outcome.
//!
//! The counters split the exchange: `mpi_agree_us` is the wait at the first agreement, for the
//! slowest rank's render (load imbalance, not compositing); `mpi_composite_wait_us` the time in
//! the composite's sends and receives (waiting for the partner, and the transfer);
//! `mpi_composite_work_us` its encoding and merging (rank 0's; `_max_us` the most of any
//! rank).

use std::sync::{Arc, Mutex, Weak};
use std::time::Instant;

use occult_core::{Scene, View};
use occult_raster::Frame;
use occult_render::{AlgoSpec, FrameStats, Phase, RenderError, RenderOptions, Renderer, Result};

use crate::comm::{agree, announce, first_failure, gather, outcome_bytes, Comm, CommError};
use crate::composite::composite;
use crate::partition;

/// How sort-last runs.
#[derive(Clone, Debug, Default)]
pub struct SortLastConfig {
    /// Every rank ends a frame with the composite (a broadcast after the gather), for callers
    /// whose later steps depend on the frame on every rank (`compare` checks frames and renders
    /// more where they differ). Off: only rank 0's frame is the composite.
    pub replicate: bool,
    /// A failure injected on purpose, for the tests of failure handling.
    pub fault: Option<Fault>,
    /// `lzb` as Han & Zeiger's §IV parallel local z-buffer ([`crate::plzb`]: the whole scene
    /// on every rank, the rays shared) instead of sort-last.
    pub parallel_lzb: bool,
}

/// A failure injected on purpose, for the tests of failure handling (a rank's out of memory
/// or bad data is hard to cause at a chosen moment otherwise): rank `rank` fails to build its
/// renderer (`frame` `None`), or fails in frame `frame` (0-based, counted per renderer) just
/// before the frame's agreement number `agreement` (0-based), as a renderer that failed there
/// would. A sort-last frame agrees after rendering (0) and after compositing (1); a parallel
/// local z-buffer frame ([`crate::plzb`]) before the exchanges of the plane (0), the depth
/// buffer (1) and the PVLs (2), before the replication when asked (3), and at its end.
///
/// Written `RANK`, `RANK:FRAME` or `RANK:FRAME:AGREEMENT` (agreement 0 when left out).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fault {
    /// The rank that fails.
    pub rank: usize,
    /// The frame it fails in; `None`: it fails to build its renderer.
    pub frame: Option<u64>,
    /// The agreement of the frame just before which it fails.
    pub agreement: usize,
}

impl Fault {
    /// Whether the fault strikes `rank` when it builds its renderer.
    pub fn strikes_build(&self, rank: usize) -> bool {
        self.rank == rank && self.frame.is_none()
    }

    /// The error the fault makes, naming itself.
    pub fn error(&self) -> RenderError {
        RenderError::Ranks(format!("failure injected for a test ({self})"))
    }
}

/// A renderer's frames, counted for its [`Fault`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FaultClock {
    fault: Option<Fault>,
    frames: u64,
}

impl FaultClock {
    pub(crate) fn new(fault: Option<Fault>) -> Self {
        Self { fault, frames: 0 }
    }

    /// Begins a frame: the fault, when it strikes `rank` in this frame.
    pub(crate) fn next_frame(&mut self, rank: usize) -> Option<Fault> {
        let frame = self.frames;
        self.frames += 1;
        self.fault.filter(|f| f.rank == rank && f.frame == Some(frame))
    }
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.frame {
            None => write!(f, "building the renderer"),
            Some(frame) => write!(f, "frame {frame}, before agreement {}", self.agreement),
        }
    }
}

impl std::str::FromStr for Fault {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let bad = || format!("'{s}' is not RANK, RANK:FRAME or RANK:FRAME:AGREEMENT");
        let mut fields = s.split(':').map(|f| f.trim().parse::<u64>().map_err(|_| bad()));
        let rank = fields.next().ok_or_else(bad)??;
        let frame = fields.next().transpose()?;
        let agreement = fields.next().transpose()?.unwrap_or(0);
        if fields.next().is_some() {
            return Err(bad());
        }
        Ok(Self {
            rank: usize::try_from(rank).map_err(|_| bad())?,
            frame,
            agreement: usize::try_from(agreement).map_err(|_| bad())?,
        })
    }
}

/// Counters a sort-last frame reports on rank 0 (besides the inner renderer's, summed over
/// ranks).
pub const COUNTERS: &[&str] = &[
    "mpi_ranks",
    "mpi_render_max_us",
    "mpi_render_min_us",
    "mpi_comm_us",
    "mpi_comm_max_us",
    "mpi_bytes_sent_max",
    "mpi_bytes_total",
    "mpi_agree_us",
    "mpi_agree_max_us",
    "mpi_composite_wait_us",
    "mpi_composite_wait_max_us",
    "mpi_composite_work_us",
    "mpi_composite_work_max_us",
];

/// Ranks whose own times are reported one by one (`mpi_rank{i}_render_us`,
/// `mpi_rank{i}_comm_us`); beyond, only the extremes above.
pub const RANKS_REPORTED: usize = 16;
const RANK_RENDER_US: [&str; 16] = [
    "mpi_rank0_render_us",
    "mpi_rank1_render_us",
    "mpi_rank2_render_us",
    "mpi_rank3_render_us",
    "mpi_rank4_render_us",
    "mpi_rank5_render_us",
    "mpi_rank6_render_us",
    "mpi_rank7_render_us",
    "mpi_rank8_render_us",
    "mpi_rank9_render_us",
    "mpi_rank10_render_us",
    "mpi_rank11_render_us",
    "mpi_rank12_render_us",
    "mpi_rank13_render_us",
    "mpi_rank14_render_us",
    "mpi_rank15_render_us",
];
const RANK_COMM_US: [&str; 16] = [
    "mpi_rank0_comm_us",
    "mpi_rank1_comm_us",
    "mpi_rank2_comm_us",
    "mpi_rank3_comm_us",
    "mpi_rank4_comm_us",
    "mpi_rank5_comm_us",
    "mpi_rank6_comm_us",
    "mpi_rank7_comm_us",
    "mpi_rank8_comm_us",
    "mpi_rank9_comm_us",
    "mpi_rank10_comm_us",
    "mpi_rank11_comm_us",
    "mpi_rank12_comm_us",
    "mpi_rank13_comm_us",
    "mpi_rank14_comm_us",
    "mpi_rank15_comm_us",
];

/// The last scene split and this rank's part of it (`None`: the split left it nothing).
type PartCache = Mutex<Option<(Weak<Scene>, Option<Arc<Scene>>)>>;

fn ranks_error(e: CommError) -> RenderError {
    RenderError::Ranks(e.to_string())
}

/// Options whose [`RenderOptions::build_around`] builds every renderer sort-last over
/// `comm`'s ranks (see the module doc). Every rank must build the same renderers in the same
/// order, and render the same views, as the commands do when each rank runs them.
pub fn sort_last_options(comm: Arc<dyn Comm>, base: RenderOptions, config: SortLastConfig) -> RenderOptions {
    // The last scene split and this rank's part of it: `compare` builds several renderers of
    // one scene, which then share the part.
    let cache: Arc<PartCache> = Arc::new(Mutex::new(None));
    let hook = move |scene: Arc<Scene>, options: &RenderOptions, spec: &AlgoSpec| -> Result<Box<dyn Renderer>> {
        if config.parallel_lzb && spec.algorithm.name() == "lzb" {
            let built = match config.fault {
                Some(fault) if fault.strikes_build(comm.rank()) => Err(fault.error()),
                _ => crate::plzb::ParallelLzb::new(Arc::clone(&comm), scene, options, spec, &config),
            };
            let outcome = built.as_ref().map(|_| ()).map_err(|e| e.to_string());
            agree(comm.as_ref(), outcome).map_err(ranks_error)?;
            return Ok(Box::new(built.expect("agreed that every rank built")) as Box<dyn Renderer>);
        }
        let built = build_part(&comm, &cache, &scene, options, spec, &config);
        let outcome = built.as_ref().map(|_| ()).map_err(|e| e.to_string());
        agree(comm.as_ref(), outcome).map_err(ranks_error)?;
        let inner = built.expect("agreed that every rank built");
        Ok(Box::new(SortLast {
            comm: Arc::clone(&comm),
            name: spec.algorithm.name(),
            conservative: inner.as_ref().is_none_or(|r| r.is_conservative()),
            inner,
            replicate: config.replicate,
            faults: FaultClock::new(config.fault),
        }) as Box<dyn Renderer>)
    };
    RenderOptions {
        build_around: Some(Arc::new(hook)),
        ..base
    }
}

/// This rank's renderer over its part (`None`: the split left it nothing).
fn build_part(
    comm: &Arc<dyn Comm>,
    cache: &PartCache,
    scene: &Arc<Scene>,
    options: &RenderOptions,
    spec: &AlgoSpec,
    config: &SortLastConfig,
) -> Result<Option<Box<dyn Renderer>>> {
    if let Some(fault) = config.fault.filter(|f| f.strikes_build(comm.rank())) {
        return Err(fault.error());
    }

    let mut cache = cache
        .lock()
        .map_err(|_| RenderError::Ranks("a rank's builder panicked".into()))?;
    let part = match cache.as_ref() {
        Some((whole, part)) if whole.upgrade().is_some_and(|w| Arc::ptr_eq(&w, scene)) => part.clone(),
        _ => {
            let part = partition::part(scene, comm.size(), comm.rank())
                .map_err(|e| RenderError::Ranks(format!("splitting the scene: {e}")))?;
            *cache = Some((Arc::downgrade(scene), part.clone()));
            part
        }
    };
    drop(cache);
    part.map(|part| spec.build(part, options)).transpose()
}

/// A renderer over this rank's part, composited across ranks (see the module doc).
pub struct SortLast {
    comm: Arc<dyn Comm>,
    name: &'static str,
    conservative: bool,
    inner: Option<Box<dyn Renderer>>,
    replicate: bool,
    faults: FaultClock,
}

/// What one rank reports to rank 0 after a frame, as little-endian u64s (then its outcome).
const REPORT_FIELDS: usize = 11;

impl SortLast {
    /// This rank's part of the frame (a cleared frame when the split left it nothing).
    fn render_part(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        match &mut self.inner {
            Some(r) => r.render(view, frame),
            None => {
                if frame.width() != view.width() || frame.height() != view.height() {
                    Err(RenderError::FrameSizeMismatch {
                        frame_width: frame.width(),
                        frame_height: frame.height(),
                        view_width: view.width(),
                        view_height: view.height(),
                    })
                } else {
                    frame.clear();
                    Ok(FrameStats::default())
                }
            }
        }
    }
}

impl Renderer for SortLast {
    fn name(&self) -> &'static str {
        self.name
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let start = Instant::now();
        let comm = Arc::clone(&self.comm);
        let comm = comm.as_ref();
        let fault_now = self.faults.next_frame(comm.rank());
        let fault = |agreement| fault_now.filter(|f| f.agreement == agreement);
        let rendered = match fault(0) {
            Some(f) => Err(f.error()),
            None => self.render_part(view, frame),
        };
        let render_time = start.elapsed();
        // Agreement 0: every rank rendered. Its time is the wait for the slowest rank's render.
        let outcome = rendered.as_ref().map(|_| ()).map_err(|e| e.to_string());
        let comm_start = Instant::now();
        agree(comm, outcome).map_err(ranks_error)?;
        let agree_time = comm_start.elapsed();
        let mut stats = rendered.expect("agreed that every rank rendered");
        let cost = composite(comm, frame, self.replicate).map_err(ranks_error)?;
        let comm_time = comm_start.elapsed();
        // Agreement 1, with the report: every rank composited (a defect found in the exchange,
        // which every rank finished, is this rank's failure).
        let outcome = match (&cost.defect, fault(1)) {
            (Some(defect), _) => Err(defect.to_string()),
            (None, Some(f)) => Err(f.error().to_string()),
            (None, None) => Ok(()),
        };
        let report: [u64; REPORT_FIELDS] = [
            render_time.as_micros() as u64,
            comm_time.as_micros() as u64,
            cost.bytes_sent,
            stats.triangles_submitted,
            stats.triangles_rasterized,
            stats.fragments_written,
            stats.nodes_visited,
            stats.boxes_tested,
            agree_time.as_micros() as u64,
            cost.wait.as_micros() as u64,
            cost.work.as_micros() as u64,
        ];
        let mut bytes: Vec<u8> = report.iter().flat_map(|v| v.to_le_bytes()).collect();
        bytes.extend(outcome_bytes(&outcome));
        let all = gather(comm, &bytes).map_err(ranks_error)?;
        let verdict = match &all {
            None => None,
            Some(all) => match all
                .iter()
                .enumerate()
                .map(|(rank, b)| decode_report(rank, b))
                .collect::<std::result::Result<Vec<_>, _>>()
            {
                Err(e) => Some((0, e.to_string())),
                Ok(reports) => {
                    let failure = first_failure(&reports.iter().map(|(_, o)| o.clone()).collect::<Vec<_>>());
                    if failure.is_none() {
                        add_report(&mut stats, &reports);
                    }
                    failure
                }
            },
        };
        announce(comm, verdict).map_err(ranks_error)?;
        stats.phases.add(Phase::Other, comm_time);
        stats.total = start.elapsed();
        Ok(stats)
    }

    fn memory_bytes(&self) -> usize {
        self.inner.as_ref().map_or(0, |r| r.memory_bytes())
    }

    fn is_conservative(&self) -> bool {
        self.conservative
    }
}

/// A rank's report: its fields and its outcome ([`outcome_bytes`]).
type Report = ([u64; REPORT_FIELDS], Vec<u8>);

fn decode_report(rank: usize, bytes: &[u8]) -> std::result::Result<Report, CommError> {
    if bytes.len() < REPORT_FIELDS * 8 {
        return Err(CommError::Malformed {
            peer: rank,
            reason: format!("a frame report of {} bytes", bytes.len()),
        });
    }
    let (fields, outcome) = bytes.split_at(REPORT_FIELDS * 8);
    let mut out = [0u64; REPORT_FIELDS];
    for (o, b) in out.iter_mut().zip(fields.chunks_exact(8)) {
        *o = u64::from_le_bytes(b.try_into().expect("chunks of 8"));
    }
    Ok((out, outcome.to_vec()))
}

/// Rank 0's counters from every rank's report (its own among them).
fn add_report(stats: &mut FrameStats, reports: &[Report]) {
    // Counts are the whole scene's: every rank's added (rank 0's own are in `stats`).
    for (r, _) in &reports[1..] {
        stats.triangles_submitted += r[3];
        stats.triangles_rasterized += r[4];
        stats.fragments_written += r[5];
        stats.nodes_visited += r[6];
        stats.boxes_tested += r[7];
    }
    let max = |field: usize| reports.iter().map(|(r, _)| r[field]).max().unwrap_or(0);
    let root = &reports[0].0;
    let c = &mut stats.counters;
    c.add("mpi_ranks", reports.len() as u64);
    c.add("mpi_render_max_us", max(0));
    c.add(
        "mpi_render_min_us",
        reports.iter().map(|(r, _)| r[0]).min().unwrap_or(0),
    );
    c.add("mpi_comm_us", root[1]);
    c.add("mpi_comm_max_us", max(1));
    c.add("mpi_bytes_sent_max", max(2));
    c.add("mpi_bytes_total", reports.iter().map(|(r, _)| r[2]).sum());
    c.add("mpi_agree_us", root[8]);
    c.add("mpi_agree_max_us", max(8));
    c.add("mpi_composite_wait_us", root[9]);
    c.add("mpi_composite_wait_max_us", max(9));
    c.add("mpi_composite_work_us", root[10]);
    c.add("mpi_composite_work_max_us", max(10));
    for (rank, (r, _)) in reports.iter().enumerate().take(RANKS_REPORTED) {
        c.add(RANK_RENDER_US[rank], r[0]);
        c.add(RANK_COMM_US[rank], r[1]);
    }
}
