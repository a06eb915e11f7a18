//! Helper threads of banded draws: threads of the rasterizer's own that wait for the next
//! draw spinning for a while before they sleep.
//!
//! The culling renderers draw many short batches (a tenth to a few milliseconds), each after
//! some tests. Handed to a sleeping pool thread, a batch waits tens of microseconds for it to
//! wake, and the caller as long again to learn that it finished: on such batches that ate what
//! sharing the fill saved. A helper that has just finished a draw spins (then yields, then
//! sleeps) waiting for the next, and the caller spins for the helpers it waits on, so a
//! batch is shared at the cost of a few cache-line transfers.
//!
//! Protocol: the caller publishes a job (a `Fn(band)` borrowed from its stack, the bands'
//! count) and bumps a generation; every participant, the caller included, claims bands from
//! one counter until none are left. A helper announces itself (`active`) before it reads the
//! job and backs off if the caller has closed the job meanwhile; the caller closes the job
//! once every band is claimed and its own are done, then waits until no helper is active. With
//! both sides' accesses sequentially consistent, a helper either sees the job closed or the
//! caller sees it active: the borrowed job is never read after the caller returns.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::SeqCst};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a helper spins for the next job before it yields its core in the loop.
const SPIN: Duration = Duration::from_micros(50);
/// How long it waits in all (spinning, then yielding) before it sleeps.
const WAIT: Duration = Duration::from_micros(500);
/// How long the caller spins for active helpers to finish before it yields its core.
const CLOSE_SPIN: Duration = Duration::from_micros(20);

/// A job's function, its lifetime erased: only called between publication and close.
#[derive(Clone, Copy)]
struct JobRef(*const (dyn Fn(usize) + Sync));

// SAFETY: the function is `Sync`, and the protocol (module doc) keeps it alive while read.
unsafe impl Send for JobRef {}

struct Shared {
    generation: AtomicU64,
    job: Mutex<Option<JobRef>>,
    bands: AtomicUsize,
    next: AtomicUsize,
    closed: AtomicBool,
    active: AtomicUsize,
    /// A job panicked on a helper: the caller panics in turn.
    panicked: AtomicBool,
    quit: AtomicBool,
    /// Helpers asleep (to be woken at the next job).
    sleeping: AtomicUsize,
}

/// The helper threads of one rasterizer ([module doc](self)).
pub(super) struct Helpers {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl Helpers {
    /// `count` helper threads.
    ///
    /// # Errors
    /// When a thread cannot be started.
    pub(super) fn new(count: usize) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            generation: AtomicU64::new(0),
            job: Mutex::new(None),
            bands: AtomicUsize::new(0),
            next: AtomicUsize::new(0),
            closed: AtomicBool::new(true),
            active: AtomicUsize::new(0),
            panicked: AtomicBool::new(false),
            quit: AtomicBool::new(false),
            sleeping: AtomicUsize::new(0),
        });
        let mut helpers = Self {
            shared,
            threads: Vec::new(),
        };
        for k in 0..count {
            let shared = Arc::clone(&helpers.shared);
            let handle = std::thread::Builder::new()
                .name(format!("occult-band-{k}"))
                .spawn(move || help(&shared))?;
            helpers.threads.push(handle);
        }
        Ok(helpers)
    }

    /// The helper threads.
    pub(super) fn count(&self) -> usize {
        self.threads.len()
    }

    /// Runs `job(band)` for every band of `0..bands` once, on the calling thread and the
    /// helpers, and returns when all are done.
    ///
    /// # Panics
    /// When a job panicked (on a helper: its panic is reported there first).
    pub(super) fn run(&mut self, bands: usize, job: &(dyn Fn(usize) + Sync)) {
        let s = &*self.shared;
        // SAFETY: only the lifetime is erased; the job is closed and no helper is active
        // before this function returns (module doc), so the reference is never used after.
        let erased: *const (dyn Fn(usize) + Sync + 'static) =
            unsafe { std::mem::transmute(job as *const (dyn Fn(usize) + Sync)) };
        *s.job.lock().unwrap_or_else(PoisonError::into_inner) = Some(JobRef(erased));
        s.panicked.store(false, SeqCst);
        s.bands.store(bands, SeqCst);
        s.next.store(0, SeqCst);
        s.closed.store(false, SeqCst);
        s.generation.fetch_add(1, SeqCst);
        if s.sleeping.load(SeqCst) > 0 {
            for t in &self.threads {
                t.thread().unpark();
            }
        }
        /// Closes the job and waits for the helpers, also when a job panics here.
        struct Close<'a>(&'a Shared);
        impl Drop for Close<'_> {
            fn drop(&mut self) {
                self.0.closed.store(true, SeqCst);
                // A helper counted active may be descheduled: spin briefly, then yield the core.
                let since = Instant::now();
                while self.0.active.load(SeqCst) != 0 {
                    if since.elapsed() < CLOSE_SPIN {
                        std::hint::spin_loop();
                    } else {
                        std::thread::yield_now();
                    }
                }
                *self.0.job.lock().unwrap_or_else(PoisonError::into_inner) = None;
            }
        }
        let close = Close(s);
        claim_bands(s, job);
        drop(close);
        assert!(
            !s.panicked.swap(false, SeqCst),
            "a banded draw panicked on a helper thread"
        );
    }
}

impl Drop for Helpers {
    fn drop(&mut self) {
        self.shared.quit.store(true, SeqCst);
        for t in &self.threads {
            t.thread().unpark();
        }
        for t in self.threads.drain(..) {
            // A helper never panics outside a job, whose panic it catches.
            let _ = t.join();
        }
    }
}

/// Runs the bands not yet claimed.
fn claim_bands(s: &Shared, job: &(dyn Fn(usize) + Sync)) {
    let bands = s.bands.load(SeqCst);
    loop {
        let b = s.next.fetch_add(1, SeqCst);
        if b >= bands {
            return;
        }
        job(b);
    }
}

/// A helper's loop: wait for a new generation, take part in its job, repeat.
fn help(s: &Shared) {
    let mut seen = s.generation.load(SeqCst);
    loop {
        let since = Instant::now();
        loop {
            if s.quit.load(SeqCst) {
                return;
            }
            if s.generation.load(SeqCst) != seen {
                break;
            }
            let waited = since.elapsed();
            if waited < SPIN {
                std::hint::spin_loop();
            } else if waited < WAIT {
                std::thread::yield_now();
            } else {
                // Counted asleep before the generation is read again, and the caller reads the
                // count after bumping it: one of the two sees the other, so no wake-up is lost
                // (and an unpark that comes first leaves its token for the park).
                s.sleeping.fetch_add(1, SeqCst);
                if s.generation.load(SeqCst) == seen && !s.quit.load(SeqCst) {
                    std::thread::park();
                }
                s.sleeping.fetch_sub(1, SeqCst);
            }
        }
        seen = s.generation.load(SeqCst);
        if s.closed.load(SeqCst) {
            // Finished already: not worth announcing (the check after announcing is the one
            // that counts).
            continue;
        }
        s.active.fetch_add(1, SeqCst);
        if !s.closed.load(SeqCst) {
            let job = *s.job.lock().unwrap_or_else(PoisonError::into_inner);
            if let Some(JobRef(f)) = job {
                // SAFETY: the job is open and this helper active: the caller keeps `f` alive
                // until it sees no helper active (module doc).
                let f = unsafe { &*f };
                if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| claim_bands(s, f))).is_err() {
                    s.panicked.store(true, SeqCst);
                }
            }
        }
        s.active.fetch_sub(1, SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every band runs exactly once per run, over many runs back to back and after the helpers
    /// fell asleep; a job that panics is reported to the caller, and the helpers go on.
    #[test]
    fn every_band_runs_once_and_panics_reach_the_caller() {
        use std::sync::atomic::AtomicU32;
        let mut helpers = Helpers::new(3).expect("three threads start");
        let counts: Vec<AtomicU32> = (0..7).map(|_| AtomicU32::new(0)).collect();
        for round in 0..2000u32 {
            let bands = 1 + (round % 7) as usize;
            helpers.run(bands, &|b| {
                counts[b].fetch_add(1, SeqCst);
            });
            if round % 500 == 499 {
                // Long enough for every helper to fall asleep.
                std::thread::sleep(WAIT * 4);
            }
        }
        let want: Vec<u32> = (0..7u32)
            .map(|b| (0..2000u32).filter(|r| (r % 7) >= b).count() as u32)
            .collect();
        let got: Vec<u32> = counts.iter().map(|c| c.load(SeqCst)).collect();
        assert_eq!(got, want);
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            helpers.run(64, &|b| {
                if b == 63 {
                    panic!("band 63");
                }
            })
        }));
        assert!(caught.is_err(), "the panic reaches the caller");
        let ran = AtomicU32::new(0);
        helpers.run(5, &|_| {
            ran.fetch_add(1, SeqCst);
        });
        assert_eq!(ran.load(SeqCst), 5, "the helpers survive a panic");
    }
}
