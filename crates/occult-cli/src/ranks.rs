//! Ranks under `mpirun` (feature `mpi`): the commands run unchanged on every rank; renderers
//! are built sort-last over the ranks (`occult-mpi`); rank 0 alone prints and writes files.
//!
//! Without the feature, or when not started by `mpirun`, there is one rank and nothing here
//! changes what a command does.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock, Weak};

use anyhow::Result;
use occult_mpi::{Comm, CommError, SortLastConfig};
use occult_render::{RenderError, RenderOptions};

/// This process's rank of the run, held weakly: `main` owns the communicator and drops it
/// (finalising MPI) when the command is over.
static COMM: OnceLock<Weak<dyn Comm>> = OnceLock::new();

/// `--mpi-lzb`: `lzb` as §IV's parallel local z-buffer instead of sort-last.
static PARALLEL_LZB: AtomicBool = AtomicBool::new(false);

/// Sets `--mpi-lzb` for the renderers built from now on.
pub fn set_parallel_lzb(on: bool) {
    PARALLEL_LZB.store(on, Ordering::Relaxed);
}

/// Environment variable that makes one rank fail, for the tests of failure handling (a rank's
/// out-of-memory is otherwise hard to cause on purpose): `RANK` fails to build its renderers,
/// `RANK:FRAME[:AGREEMENT]` fails in a frame ([`occult_mpi::Fault`]).
pub const FAIL_RANK_VAR: &str = "OCCULT_MPI_FAIL_RANK";

/// This process's rank as the launcher tells it, before MPI is started (0 outside `mpirun`).
pub fn launcher_rank() -> usize {
    ["OMPI_COMM_WORLD_RANK", "PMI_RANK"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.parse().ok())
        .unwrap_or(0)
}

/// Whether `mpirun` started this process.
#[cfg(feature = "mpi")]
pub fn launched_by_mpirun() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"]
        .iter()
        .any(|v| std::env::var_os(v).is_some())
}

/// Starts MPI when `mpirun` started this process: the communicator, which the caller keeps
/// until the command is over. `None` without the feature or outside `mpirun`.
///
/// # Errors
/// MPI that cannot start as occult needs it.
pub fn start() -> Result<Option<Arc<dyn Comm>>> {
    #[cfg(feature = "mpi")]
    if launched_by_mpirun() {
        let comm: Arc<dyn Comm> = Arc::new(occult_mpi::mpi_comm::MpiComm::init()?);
        // Set once, here, before any command runs.
        let _ = COMM.set(Arc::downgrade(&comm));
        return Ok(Some(comm));
    }
    Ok(None)
}

fn comm() -> Option<Arc<dyn Comm>> {
    COMM.get().and_then(Weak::upgrade)
}

/// Whether this rank prints and writes files (rank 0, or the only process).
pub fn is_root() -> bool {
    comm().map_or(launcher_rank() == 0, |c| c.rank() == 0)
}

/// The options commands build renderers with: sort-last over the ranks under `mpirun`
/// (`replicate`: every rank ends a frame with the composite, for commands whose later steps
/// read the frame), the defaults otherwise.
pub fn render_options(replicate: bool) -> RenderOptions {
    let Some(comm) = comm() else {
        return RenderOptions::default();
    };
    let config = SortLastConfig {
        replicate,
        fault: std::env::var(FAIL_RANK_VAR).ok().and_then(|v| v.parse().ok()),
        parallel_lzb: PARALLEL_LZB.load(Ordering::Relaxed),
    };
    occult_mpi::sort_last_options(comm, RenderOptions::default(), config)
}

/// `outcome` once every rank has its own: under `mpirun`, a failure on any rank becomes the
/// same error on every rank (naming the rank), so that rank 0 reports it and no rank waits on a
/// failed one.
///
/// # Errors
/// This rank's error, or another rank's.
pub fn agree<T>(outcome: Result<T>) -> Result<T> {
    let Some(comm) = comm() else {
        return outcome;
    };
    let mine = outcome.as_ref().map(|_| ()).map_err(crate::one_line);
    occult_mpi::agree(comm.as_ref(), mine)?;
    outcome
}

/// Whether every rank has this error (a failure agreed on, so every rank ends alike); other
/// errors of one rank end the whole run at once instead ([`abort`]).
pub fn is_agreed(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(c.downcast_ref::<CommError>(), Some(CommError::RankFailed { .. }))
            || matches!(c.downcast_ref::<RenderError>(), Some(RenderError::Ranks(_)))
    })
}

/// Ends every rank of the run at once (MPI_Abort): for an error on this rank alone, which the
/// others would otherwise wait on.
pub fn abort(comm: &Arc<dyn Comm>) -> ! {
    comm.abort(1)
}
