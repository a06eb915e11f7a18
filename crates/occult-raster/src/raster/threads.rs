//! The job system: how a draw's parallel phases are handed to the threads.

/// The threads a draw's parallel phases run on: a rasterizer's own pool, or (`None`) the pool
/// the caller runs in, rayon's global one outside any.
pub(super) struct Workers<'a> {
    pub(super) pool: Option<&'a rayon::ThreadPool>,
    pub(super) threads: usize,
}

impl Workers<'_> {
    /// Runs `job` on each of `jobs` and returns the results in the jobs' order. On one thread,
    /// or for a single job, on the calling thread; else on up to `threads` tasks spawned into
    /// the pool, each taking the next job from a counter when it finishes one, so any thread
    /// may run any job (callers' jobs give the same results on any thread, in any order), and
    /// a thread that is busy or blocked elsewhere only means another runs more. (With as many
    /// jobs as threads, as sort-last's workers are, a thread that runs slower still holds up
    /// the end by its share.)
    ///
    /// The tasks are spawned from the calling thread, which (outside the pool) injects them,
    /// waking a sleeping thread per task. Not `install` plus `rayon::join`: a join's second
    /// half waits on the first thread's queue to be stolen, which after the pool has idled
    /// starts it late (often on the same thread), while tasks spawned from outside start at
    /// once (`cargo run --release -p occult-bench --example thread_scaling wake 60` shows
    /// both). A caller inside the pool spawns onto its own queue and runs the jobs itself while
    /// it waits, as a join does.
    pub(super) fn share<T: Send, R: Send>(&self, jobs: Vec<T>, job: impl Fn(T) -> R + Sync) -> Vec<R> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::{Mutex, PoisonError};
        if self.threads <= 1 || jobs.len() <= 1 {
            return jobs.into_iter().map(job).collect();
        }
        let tasks = self.threads.min(jobs.len());
        // No job runs while a slot is locked, so no slot is poisoned; a poisoned one would
        // still be read.
        let slots: Vec<Mutex<(Option<T>, Option<R>)>> = jobs.into_iter().map(|j| Mutex::new((Some(j), None))).collect();
        let lock = |i: usize| slots[i].lock().unwrap_or_else(PoisonError::into_inner);
        let next = AtomicUsize::new(0);
        let work = || loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= slots.len() {
                break;
            }
            // The counter hands each index out once.
            let taken = lock(i).0.take();
            if let Some(j) = taken {
                let r = job(j);
                lock(i).1 = Some(r);
            }
        };
        let work = &work;
        match self.pool {
            Some(p) => p.in_place_scope(|scope| (0..tasks).for_each(|_| scope.spawn(move |_| work()))),
            None => rayon::in_place_scope(|scope| (0..tasks).for_each(|_| scope.spawn(move |_| work()))),
        }
        // A job that panicked ended the scope above with its panic: every slot has its result.
        slots
            .into_iter()
            .map(|s| {
                s.into_inner()
                    .unwrap_or_else(PoisonError::into_inner)
                    .1
                    .expect("every job ran: a panic in one ends the scope with it")
            })
            .collect()
    }
}
