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
//! failed rank ends the run with one error, never a hang); composite; gather the ranks' times
//! and counts to rank 0, which reports them as counters (`mpi_*`, below).

use std::sync::{Arc, Mutex, Weak};
use std::time::Instant;

use occult_core::{Scene, View};
use occult_raster::Frame;
use occult_render::{AlgoSpec, FrameStats, Phase, RenderError, RenderOptions, Renderer, Result};

use crate::comm::{agree, gather, Comm, CommError};
use crate::composite::composite;
use crate::partition;

/// How sort-last runs.
#[derive(Clone, Debug, Default)]
pub struct SortLastConfig {
    /// Every rank ends a frame with the composite (a broadcast after the gather), for callers
    /// whose later steps depend on the frame on every rank (`compare` checks frames and renders
    /// more where they differ). Off: only rank 0's frame is the composite.
    pub replicate: bool,
    /// Fault injection for tests of failure handling: this rank fails to build its renderer.
    pub fail_rank: Option<usize>,
    /// `lzb` as Han & Zeiger's §IV parallel local z-buffer ([`crate::plzb`]: the whole scene
    /// on every rank, the rays shared) instead of sort-last.
    pub parallel_lzb: bool,
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
            let built = if config.fail_rank == Some(comm.rank()) {
                Err(RenderError::Ranks("failure injected for a test (fail_rank)".into()))
            } else {
                crate::plzb::ParallelLzb::new(Arc::clone(&comm), scene, options, spec, config.replicate)
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
    if config.fail_rank == Some(comm.rank()) {
        return Err(RenderError::Ranks("failure injected for a test (fail_rank)".into()));
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
}

/// What one rank reports to rank 0 after a frame, as little-endian u64s.
const REPORT_FIELDS: usize = 8;

impl Renderer for SortLast {
    fn name(&self) -> &'static str {
        self.name
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let start = Instant::now();
        let comm = self.comm.as_ref();
        let rendered = match &mut self.inner {
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
        };
        let render_time = start.elapsed();
        let outcome = rendered.as_ref().map(|_| ()).map_err(|e| e.to_string());
        let comm_start = Instant::now();
        agree(comm, outcome).map_err(ranks_error)?;
        let mut stats = rendered.expect("agreed that every rank rendered");
        let cost = composite(comm, frame, self.replicate).map_err(ranks_error)?;
        let comm_time = comm_start.elapsed();
        let report: [u64; REPORT_FIELDS] = [
            render_time.as_micros() as u64,
            comm_time.as_micros() as u64,
            cost.bytes_sent,
            stats.triangles_submitted,
            stats.triangles_rasterized,
            stats.fragments_written,
            stats.nodes_visited,
            stats.boxes_tested,
        ];
        let bytes: Vec<u8> = report.iter().flat_map(|v| v.to_le_bytes()).collect();
        let all = gather(comm, &bytes).map_err(ranks_error)?;
        stats.phases.add(Phase::Other, comm_time);
        if let Some(all) = all {
            let reports = all
                .iter()
                .enumerate()
                .map(|(rank, b)| decode_report(rank, b))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(ranks_error)?;
            // Counts are the whole scene's: every rank's added (rank 0's own are in `stats`).
            for r in &reports[1..] {
                stats.triangles_submitted += r[3];
                stats.triangles_rasterized += r[4];
                stats.fragments_written += r[5];
                stats.nodes_visited += r[6];
                stats.boxes_tested += r[7];
            }
            let c = &mut stats.counters;
            c.add("mpi_ranks", reports.len() as u64);
            c.add("mpi_render_max_us", reports.iter().map(|r| r[0]).max().unwrap_or(0));
            c.add("mpi_render_min_us", reports.iter().map(|r| r[0]).min().unwrap_or(0));
            c.add("mpi_comm_us", reports[0][1]);
            c.add("mpi_comm_max_us", reports.iter().map(|r| r[1]).max().unwrap_or(0));
            c.add("mpi_bytes_sent_max", reports.iter().map(|r| r[2]).max().unwrap_or(0));
            c.add("mpi_bytes_total", reports.iter().map(|r| r[2]).sum());
            for (rank, r) in reports.iter().enumerate().take(RANKS_REPORTED) {
                c.add(RANK_RENDER_US[rank], r[0]);
                c.add(RANK_COMM_US[rank], r[1]);
            }
        }
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

fn decode_report(rank: usize, bytes: &[u8]) -> std::result::Result<[u64; REPORT_FIELDS], CommError> {
    if bytes.len() != REPORT_FIELDS * 8 {
        return Err(CommError::Malformed {
            peer: rank,
            reason: format!("a frame report of {} bytes", bytes.len()),
        });
    }
    let mut out = [0u64; REPORT_FIELDS];
    for (o, b) in out.iter_mut().zip(bytes.chunks_exact(8)) {
        *o = u64::from_le_bytes(b.try_into().expect("chunks of 8"));
    }
    Ok(out)
}
