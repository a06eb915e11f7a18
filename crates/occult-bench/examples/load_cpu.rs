//! CPU time per load of the load benchmark's files: the height field in every format and, with
//! `OCCULT_MODELS` set, the real models. Criterion's figures are wall-clock; on a shared machine
//! they include the time other processes held the core. This reports the thread's own CPU time
//! (`/proc/thread-self/schedstat`, Linux), the mean over many loads, as MB/s of input.
//!
//!     cargo run --release -p occult-bench --example load_cpu [RUNS]

use std::path::Path;

use occult_scenes::load::load_bytes;

/// Nanoseconds this thread has run (the first field of `/proc/thread-self/schedstat`).
fn thread_cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .expect("/proc/thread-self/schedstat (Linux) holds the thread's run time")
}

fn main() {
    let runs: u64 = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(50);
    let mut files = occult_bench::load_grid_files();
    if let Some(root) = std::env::var_os("OCCULT_MODELS") {
        files.extend(occult_bench::model_files(Path::new(&root)));
    }
    println!("file, MB, CPU ms per load (mean of {runs}), MB/s");
    for (name, path, bytes) in &files {
        // The scheduler updates the run time at ticks and switches: the mean over many loads.
        load_bytes(path, bytes).expect("the bench's files load");
        let start = thread_cpu_ns();
        for _ in 0..runs {
            drop(load_bytes(path, bytes).expect("the bench's files load"));
        }
        let per_load = (thread_cpu_ns() - start) as f64 / runs as f64;
        let mb = bytes.len() as f64 / 1e6;
        println!("{name}, {mb:.1}, {:.2}, {:.0}", per_load / 1e6, mb / (per_load / 1e9));
    }
}
