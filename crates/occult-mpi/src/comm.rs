//! The transport: a [`Comm`] is one rank's view of a group of ranks that exchange byte
//! messages, as an MPI communicator is. Two transports implement it: [`ThreadComm`] (ranks are
//! threads of one process, for tests and the default build) and, with the `mpi` feature,
//! `MpiComm` (ranks are MPI processes).
//!
//! Messages between one pair of ranks arrive in the order they were sent (MPI's
//! non-overtaking rule; channels keep it too). Every algorithm of this crate is written with
//! [`Comm::send`] and [`Comm::recv`] only, ordered so that no rank waits on a send: the lower
//! rank of a pair sends first. The collectives below ([`gather`], [`broadcast`], [`agree`])
//! are built from them, rooted at rank 0.

use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};

use thiserror::Error;

/// Errors of the transport and of ranks that failed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CommError {
    /// A peer went away (its thread ended or panicked, or MPI reported an error).
    #[error("rank {peer} is gone: {reason}")]
    PeerGone {
        /// The rank that cannot be reached.
        peer: usize,
        /// What the transport said.
        reason: String,
    },
    /// A message did not have the layout the protocol expects.
    #[error("malformed message from rank {peer}: {reason}")]
    Malformed {
        /// The sender.
        peer: usize,
        /// What was wrong.
        reason: String,
    },
    /// A rank failed (bad scene, out of memory, a renderer's error); every rank returns this
    /// same error, and rank 0 prints it.
    #[error("rank {rank} of {size}: {message}")]
    RankFailed {
        /// The first rank that failed.
        rank: usize,
        /// Ranks in all.
        size: usize,
        /// Its error, on one line.
        message: String,
    },
}

/// One rank's end of a group of ranks.
pub trait Comm: Send + Sync {
    /// This rank, in `0..size()`.
    fn rank(&self) -> usize;
    /// Ranks in the group (at least 1).
    fn size(&self) -> usize;
    /// Sends `bytes` to rank `to` (not this rank).
    ///
    /// # Errors
    /// [`CommError::PeerGone`].
    fn send(&self, to: usize, bytes: &[u8]) -> Result<(), CommError>;
    /// Receives the next message from rank `from` (not this rank), waiting for it.
    ///
    /// # Errors
    /// [`CommError::PeerGone`].
    fn recv(&self, from: usize) -> Result<Vec<u8>, CommError>;
    /// The transport's name, for reports (`threads` or `mpi`).
    fn transport(&self) -> &'static str;
    /// Ends every rank of the run with exit status `code` (MPI_Abort): for a failure on one
    /// rank that the others cannot learn of. Thread ranks end the process.
    fn abort(&self, code: i32) -> ! {
        std::process::exit(code)
    }
}

/// Ranks as threads of one process, linked by channels: the transport of the default build.
pub struct ThreadComm {
    rank: usize,
    to: Vec<Sender<Vec<u8>>>,
    from: Vec<Mutex<Receiver<Vec<u8>>>>,
}

impl ThreadComm {
    /// `size` linked ranks, `result[r]` being rank `r`'s end.
    ///
    /// # Panics
    /// If `size` is 0.
    pub fn group(size: usize) -> Vec<ThreadComm> {
        assert!(size > 0, "a group has at least one rank");
        // channels[from][to]
        let mut senders: Vec<Vec<Option<Sender<Vec<u8>>>>> = (0..size).map(|_| Vec::new()).collect();
        let mut receivers: Vec<Vec<Option<Receiver<Vec<u8>>>>> =
            (0..size).map(|_| (0..size).map(|_| None).collect()).collect();
        for (from, row) in senders.iter_mut().enumerate() {
            for to_receivers in receivers.iter_mut() {
                let (s, r) = channel();
                row.push(Some(s));
                to_receivers[from] = Some(r);
            }
        }
        senders
            .into_iter()
            .zip(receivers)
            .enumerate()
            .map(|(rank, (to, from))| ThreadComm {
                rank,
                to: to.into_iter().map(|s| s.expect("made above")).collect(),
                from: from.into_iter().map(|r| Mutex::new(r.expect("made above"))).collect(),
            })
            .collect()
    }
}

impl Comm for ThreadComm {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.to.len()
    }
    fn send(&self, to: usize, bytes: &[u8]) -> Result<(), CommError> {
        self.to[to].send(bytes.to_vec()).map_err(|_| CommError::PeerGone {
            peer: to,
            reason: "its thread ended".into(),
        })
    }
    fn recv(&self, from: usize) -> Result<Vec<u8>, CommError> {
        let receiver = self.from[from].lock().map_err(|_| CommError::PeerGone {
            peer: from,
            reason: "a receiver of this rank panicked".into(),
        })?;
        receiver.recv().map_err(|_| CommError::PeerGone {
            peer: from,
            reason: "its thread ended".into(),
        })
    }
    fn transport(&self) -> &'static str {
        "threads"
    }
}

/// Runs `f` on `size` thread ranks at once and returns their results in rank order (a panic
/// of a rank is returned as its `Err`, after the others ended: a rank that waits on it sees
/// [`CommError::PeerGone`] instead of hanging, as its end of the channels goes with it).
pub fn run_threads<R: Send>(size: usize, f: impl Fn(&Arc<dyn Comm>) -> R + Sync) -> Vec<std::thread::Result<R>> {
    let comms = ThreadComm::group(size);
    std::thread::scope(|s| {
        let handles: Vec<_> = comms
            .into_iter()
            .map(|comm| {
                let f = &f;
                let comm: Arc<dyn Comm> = Arc::new(comm);
                s.spawn(move || f(&comm))
            })
            .collect();
        handles.into_iter().map(|h| h.join()).collect()
    })
}

/// Every rank's `bytes`, at rank 0 in rank order (`None` on the other ranks).
///
/// # Errors
/// Transport errors.
pub fn gather(comm: &dyn Comm, bytes: &[u8]) -> Result<Option<Vec<Vec<u8>>>, CommError> {
    if comm.rank() != 0 {
        comm.send(0, bytes)?;
        return Ok(None);
    }
    let mut all = vec![bytes.to_vec()];
    for from in 1..comm.size() {
        all.push(comm.recv(from)?);
    }
    Ok(Some(all))
}

/// Rank 0's `bytes` on every rank (the others' `bytes` are ignored). Sent along a binary tree:
/// ⌈log2 size⌉ steps.
///
/// # Errors
/// Transport errors.
pub fn broadcast(comm: &dyn Comm, bytes: Vec<u8>) -> Result<Vec<u8>, CommError> {
    let (rank, size) = (comm.rank(), comm.size());
    let mut data = if rank == 0 { Some(bytes) } else { None };
    let mut step = 1;
    while step < size {
        if rank < step {
            let to = rank + step;
            if to < size {
                comm.send(to, data.as_ref().expect("ranks below step hold the data"))?;
            }
        } else if rank < 2 * step {
            data = Some(comm.recv(rank - step)?);
        }
        step *= 2;
    }
    Ok(data.expect("every rank receives by the last step"))
}

/// Whether every rank succeeded: each rank gives its own outcome, and all return the same
/// answer, the first failure by rank (rank 0 then prints one error, and no rank waits on a
/// failed one). Call it after every step that may fail on some ranks only (loading, building,
/// rendering) before the next exchange.
///
/// A rank that failed between two agreements calls the next one with its error, and every
/// rank returns there: so a frame whose exchanges each begin with an agreement ends on every
/// rank at the same point, whichever rank failed where ([`crate::plzb`], [`crate::sortlast`]).
///
/// # Errors
/// [`CommError::RankFailed`] naming the first failed rank; transport errors.
pub fn agree(comm: &dyn Comm, outcome: Result<(), String>) -> Result<(), CommError> {
    let verdict = gather(comm, &outcome_bytes(&outcome))?.and_then(|all| first_failure(&all));
    announce(comm, verdict)
}

/// `outcome` as a message: empty for success, a 1 and the error's text for a failure.
pub(crate) fn outcome_bytes(outcome: &Result<(), String>) -> Vec<u8> {
    match outcome {
        Ok(()) => Vec::new(),
        Err(message) => {
            let mut m = vec![1u8];
            m.extend_from_slice(message.as_bytes());
            m
        }
    }
}

/// The first failure, by rank, among the ranks' [`outcome_bytes`].
pub(crate) fn first_failure(all: &[Vec<u8>]) -> Option<(usize, String)> {
    all.iter()
        .enumerate()
        .find(|(_, m)| !m.is_empty())
        .map(|(rank, m)| (rank, String::from_utf8_lossy(&m[1..]).into_owned()))
}

/// Rank 0's `verdict` (the first failure: rank and message; `None`: none) on every rank, the
/// others' ignored: the second half of [`agree`], for callers that gathered the outcomes with
/// other data.
///
/// # Errors
/// [`CommError::RankFailed`] for a failure; transport errors.
pub(crate) fn announce(comm: &dyn Comm, verdict: Option<(usize, String)>) -> Result<(), CommError> {
    let bytes = match verdict {
        Some((rank, message)) if comm.rank() == 0 => {
            let mut v = (rank as u64).to_le_bytes().to_vec();
            v.extend_from_slice(message.as_bytes());
            v
        }
        _ => Vec::new(),
    };
    let verdict = broadcast(comm, bytes)?;
    if verdict.is_empty() {
        return Ok(());
    }
    let rank_bytes: [u8; 8] = verdict
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or_else(|| CommError::Malformed {
            peer: 0,
            reason: "a verdict shorter than its rank".into(),
        })?;
    Err(CommError::RankFailed {
        rank: u64::from_le_bytes(rank_bytes) as usize,
        size: comm.size(),
        message: String::from_utf8_lossy(&verdict[8..]).into_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gather_and_broadcast_at_every_size() {
        for size in 1..=5 {
            let out = run_threads(size, |c| {
                let g = gather(c.as_ref(), &[c.rank() as u8]).expect("threads stay");
                let b = broadcast(c.as_ref(), vec![7, c.rank() as u8]).expect("threads stay");
                (g, b)
            });
            for (rank, r) in out.into_iter().enumerate() {
                let (g, b) = r.expect("no rank panics");
                assert_eq!(b, vec![7, 0], "rank 0's message everywhere");
                if rank == 0 {
                    assert_eq!(g, Some((0..size as u8).map(|r| vec![r]).collect()));
                } else {
                    assert_eq!(g, None);
                }
            }
        }
    }

    #[test]
    fn a_failed_rank_is_one_error_everywhere() {
        let out = run_threads(3, |c| {
            let outcome = if c.rank() == 2 {
                Err("out of memory".to_string())
            } else {
                Ok(())
            };
            agree(c.as_ref(), outcome)
        });
        for r in out {
            assert_eq!(
                r.expect("no rank panics"),
                Err(CommError::RankFailed {
                    rank: 2,
                    size: 3,
                    message: "out of memory".into()
                })
            );
        }
        let ok = run_threads(2, |c| agree(c.as_ref(), Ok(())));
        assert!(ok.into_iter().all(|r| r.expect("no rank panics").is_ok()));
    }

    #[test]
    fn a_rank_that_panics_does_not_hang_the_others() {
        let out = run_threads(2, |c| {
            if c.rank() == 1 {
                panic!("rank 1 dies");
            }
            c.recv(1)
        });
        assert!(matches!(out[0], Ok(Err(CommError::PeerGone { peer: 1, .. }))));
        assert!(out[1].is_err());
    }
}
