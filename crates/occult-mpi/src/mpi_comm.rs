//! The MPI transport (feature `mpi`): ranks are the processes of `MPI_COMM_WORLD`, started by
//! `mpirun`. Messages are `MPI_BYTE` arrays of tag 0 (MPI keeps their order between a pair).
//!
//! MPI is initialised with `MPI_THREAD_SERIALIZED` and every call goes through one mutex, so
//! that the [`Comm`] can be shared as the renderers need (`Send + Sync`) while MPI sees one call
//! at a time.

use std::sync::Mutex;

use mpi::environment::Universe;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::{Destination, Source};
use mpi::Threading;

use crate::comm::{Comm, CommError};

/// `MPI_COMM_WORLD` of this process; MPI is finalised when it is dropped (every rank must drop
/// it, as every rank must have called it).
pub struct MpiComm {
    rank: usize,
    size: usize,
    world: Mutex<SimpleCommunicator>,
    // Declared last: dropped after `world`, finalising MPI.
    _universe: Universe,
}

// SAFETY: MPI was initialised with at least MPI_THREAD_SERIALIZED (checked in `init`), which
// allows calls from any thread as long as no two run at once; every call through `world` holds
// its mutex, and the universe is only dropped (finalised) once, by the owner.
unsafe impl Send for MpiComm {}
// SAFETY: as for Send: shared references only reach MPI through the mutex.
unsafe impl Sync for MpiComm {}

impl MpiComm {
    /// Initialises MPI and returns this process's rank of `MPI_COMM_WORLD`.
    ///
    /// # Errors
    /// [`CommError::PeerGone`] (peer 0) when MPI was initialised before, or does not offer
    /// serialized threading.
    pub fn init() -> Result<Self, CommError> {
        let (universe, threading) =
            mpi::initialize_with_threading(Threading::Serialized).ok_or_else(|| CommError::PeerGone {
                peer: 0,
                reason: "MPI was initialised twice".into(),
            })?;
        if threading < Threading::Serialized {
            return Err(CommError::PeerGone {
                peer: 0,
                reason: format!("this MPI offers threading {threading:?}, below the serialized level occult needs"),
            });
        }
        let world = universe.world();
        Ok(Self {
            rank: world.rank() as usize,
            size: world.size() as usize,
            world: Mutex::new(world),
            _universe: universe,
        })
    }

    fn world(&self) -> Result<std::sync::MutexGuard<'_, SimpleCommunicator>, CommError> {
        self.world.lock().map_err(|_| CommError::PeerGone {
            peer: self.rank,
            reason: "a thread panicked inside an MPI call".into(),
        })
    }
}

impl Comm for MpiComm {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }
    fn send(&self, to: usize, bytes: &[u8]) -> Result<(), CommError> {
        // MPI's default error handler aborts the job on a failed call: no error comes back.
        self.world()?.process_at_rank(to as i32).send(bytes);
        Ok(())
    }
    fn recv(&self, from: usize) -> Result<Vec<u8>, CommError> {
        let (bytes, _status) = self.world()?.process_at_rank(from as i32).receive_vec::<u8>();
        Ok(bytes)
    }
    fn transport(&self) -> &'static str {
        "mpi"
    }
    fn abort(&self, code: i32) -> ! {
        // Without the lock: a thread stuck in an MPI call holds it, and abort must still run
        // (MPI_Abort may be called from any thread at any time).
        let world = mpi::topology::SimpleCommunicator::world();
        world.abort(code)
    }
}
