//! Two threads against one on the `terrain` anchor view, measured in rounds: one draw with a
//! 1-thread rasterizer, then two with a 2-thread rasterizer, alternating in one process, so
//! that all see the same machine load. The first 2-thread draw of a round starts after its
//! pool sat idle through the 1-thread draw; the second right after the first, as in a stream
//! of frames (or criterion's back-to-back iterations). On this project's VMs the two differ:
//! a thread woken on a core that has been idle for 20 ms starts milliseconds late (see `wake`
//! below), which no split of the draw can avoid. Prints the minimum and median of each and
//! the median of the per-round ratios, which drift on a noisy machine affects least.
//!
//! `cargo run --release -p occult-bench --example thread_scaling [rounds]` (default 15).
//! `... thread_scaling one-thread N` instead draws N times with one thread only, for counting
//! instructions under a profiler (`valgrind --tool=callgrind
//! --toggle-collect='occult_raster::raster::Rasterizer::draw'`).
//! `... thread_scaling machine N` asks what the machine gives one thread, N times: before
//! each 1-thread draw (after one untimed draw), the clock (a chain of dependent additions runs
//! one per cycle) and the share of four additions per cycle that four independent chains reach
//! at that clock (all of it on an idle core with four integer ALUs; less when a neighbour on the
//! same physical core takes its ports); then the draw's time, and the correlation of draw times
//! with each probe.
//! `... thread_scaling contention N` measures what the machine itself allows: N rounds of a
//! 1-thread draw alone, then two independent 1-thread draws at once on two OS threads (own
//! rasterizer, own frame, nothing shared but the mesh). With no cost to running both cores,
//! a pair takes as long as a draw alone; the ratio of the medians, doubled, bounds what any
//! split of one draw over two threads can reach.
//! `... thread_scaling wake N` measures what starting a second thread costs on this machine,
//! N times each: (1) after the waking thread slept 1, 5 and 20 ms (so that the cores idled that
//! long), it wakes a thread blocked on a channel and stays busy for 3 ms, as a
//! draw's first worker would, and times how late the woken thread runs; (2) after a
//! two-thread pool idled 20 ms, how late the second of two 3 ms jobs starts, counted from the
//! call, and how often both ran on one thread: as the halves of a `rayon::join` run inside the
//! pool by `install` (how the rasterizer once started its draws: one hand-off into the pool,
//! then the second half waits on the first thread's queue to be stolen), and as two tasks
//! spawned from outside by `in_place_scope` (how its parallel phases start now).

use occult_core::glam::Affine3A;
use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = args.first().map(String::as_str);
    let one_thread = mode == Some("one-thread");
    let contention = mode == Some("contention");
    let machine = mode == Some("machine");
    let wake = mode == Some("wake");
    let count = |a: Option<&String>| -> Result<usize, String> {
        match a {
            Some(a) => match a.parse() {
                Ok(0) | Err(_) => Err(format!("expected a count of draws of at least 1, got `{a}`")),
                Ok(n) => Ok(n),
            },
            None => Ok(15),
        }
    };
    let pairs = count(args.get(usize::from(one_thread || contention || machine || wake)))?;
    if wake {
        return wake_latency(pairs);
    }
    let (scene, view) = occult_bench::terrain_view();
    let mesh = scene.node(scene.root()).mesh().ok_or("terrain is one mesh")?;
    let draw = Draw {
        mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let raster = |threads| {
        Rasterizer::new(RasterConfig {
            threads,
            ..RasterConfig::default()
        })
    };
    let one = || raster(1);
    // Frames are cleared on this thread, so that a clear does not wake the pool of the
    // rasterizer timed next.
    let clearer = one()?;
    // One timed draw into a cleared frame, in milliseconds.
    let timed = |r: &mut Rasterizer, frame: &mut Frame| {
        clearer.clear(frame);
        let start = Instant::now();
        let counts = r.draw(&view, frame, std::slice::from_ref(&draw), RasterMode::Full);
        (start.elapsed().as_secs_f64() * 1e3, counts)
    };
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    if one_thread {
        let mut r = one()?;
        let mut frame = Frame::new(view.width(), view.height())?;
        for _ in 0..pairs {
            let (ms, counts) = timed(&mut r, &mut frame);
            println!("1 thread: {ms:.1} ms, {counts:?}");
        }
        return Ok(());
    }
    if machine {
        let mut r = one()?;
        let mut frame = Frame::new(view.width(), view.height())?;
        // The first draw pays for first touches of the frame and the rasterizer's buffers.
        timed(&mut r, &mut frame);
        let (mut clocks, mut shares, mut times) = (Vec::new(), Vec::new(), Vec::new());
        for round in 1..=pairs {
            let Some((ghz, share)) = core_probe() else {
                return Err("the machine probe needs x86_64".into());
            };
            let (ms, counts) = timed(&mut r, &mut frame);
            println!(
                "round {round}: clock {ghz:.2} GHz, four chains at {:.0} % of four additions per cycle; \
                 draw {ms:.1} ms = {:.0} cycles per triangle at that clock",
                share * 100.0,
                ms * 1e6 * ghz / counts.triangles_submitted as f64
            );
            clocks.push(ghz);
            shares.push(share);
            times.push(ms);
        }
        println!(
            "draw time: min {:.1} ms, median {:.1} ms; its correlation with the clock {:+.2}, with the four \
             chains' share {:+.2}",
            min(&times),
            median(&times),
            correlation(&clocks, &times),
            correlation(&shares, &times)
        );
        return Ok(());
    }
    if contention {
        let mut workers = [
            (one()?, Frame::new(view.width(), view.height())?),
            (one()?, Frame::new(view.width(), view.height())?),
        ];
        let (mut alone, mut together) = (Vec::new(), Vec::new());
        for _ in 0..pairs {
            let (r, frame) = &mut workers[0];
            alone.push(timed(r, frame).0);
            let times: Vec<f64> = std::thread::scope(|s| {
                let handles: Vec<_> = workers
                    .iter_mut()
                    .map(|(r, frame)| s.spawn(|| timed(r, frame).0))
                    .collect();
                handles.into_iter().filter_map(|h| h.join().ok()).collect()
            });
            if times.len() != 2 {
                return Err("a draw thread panicked".into());
            }
            together.extend(times);
        }
        let (a, t) = (median(&alone), median(&together));
        println!(
            "1-thread draw alone: min {:.1} ms, median {a:.1} ms; two at once: min {:.1} ms, median {t:.1} ms \
             ({:+.0} %); two threads can reach at most {:.2}x one",
            min(&alone),
            min(&together),
            (t / a - 1.0) * 100.0,
            2.0 * a / t
        );
        return Ok(());
    }
    let (mut r1, mut r2) = (one()?, raster(2)?);
    let mut frame = Frame::new(view.width(), view.height())?;
    // One thread; two threads after the pool idled; two threads right after that.
    let mut times = [Vec::new(), Vec::new(), Vec::new()];
    for _ in 0..pairs {
        times[0].push(timed(&mut r1, &mut frame).0);
        times[1].push(timed(&mut r2, &mut frame).0);
        times[2].push(timed(&mut r2, &mut frame).0);
    }
    let ratio = |k: usize| median(&times[0].iter().zip(&times[k]).map(|(a, b)| a / b).collect::<Vec<_>>());
    println!(
        "1 thread: min {:.1} ms, median {:.1} ms; 2 threads, pool idle before: min {:.1} ms, median {:.1} ms \
         ({:.2}x one thread); 2 threads, right after another 2-thread draw: min {:.1} ms, median {:.1} ms \
         ({:.2}x); ratios are medians over {pairs} rounds",
        min(&times[0]),
        median(&times[0]),
        min(&times[1]),
        median(&times[1]),
        ratio(1),
        min(&times[2]),
        median(&times[2]),
        ratio(2)
    );
    Ok(())
}

/// `wake` mode (see the module doc): medians and maxima, in microseconds, of how late a thread
/// blocked on a channel runs after it is woken, for three idle times before.
fn wake_latency(rounds: usize) -> Result<(), Box<dyn std::error::Error>> {
    use std::sync::{mpsc, Mutex};
    use std::time::Duration;
    let busy = |d: Duration| {
        let t = Instant::now();
        while t.elapsed() < d {
            std::hint::spin_loop();
        }
    };
    for idle_ms in [1, 5, 20] {
        // Each message is the time it was sent; the woken thread keeps how late it got each
        // (a channel loses none, however late the thread runs).
        let (send, receive) = mpsc::channel::<Instant>();
        let woken = std::thread::spawn(move || receive.iter().map(|sent| sent.elapsed().as_secs_f64() * 1e6).collect());
        for _ in 0..rounds {
            std::thread::sleep(Duration::from_millis(idle_ms));
            send.send(Instant::now())?;
            busy(Duration::from_millis(3));
        }
        drop(send);
        let late: Vec<f64> = woken.join().map_err(|_| "the woken thread panicked")?;
        println!(
            "cores idle {idle_ms:>2} ms before: the woken thread ran {} after it was woken",
            spread(late)
        );
    }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build()?;
    let (mut joined, mut spawned) = (Vec::new(), Vec::new());
    let (mut joined_alone, mut spawned_alone) = (0, 0);
    for _ in 0..rounds {
        std::thread::sleep(Duration::from_millis(20));
        let start = Instant::now();
        let (first, second) = pool.install(|| {
            rayon::join(
                || {
                    let at = (start.elapsed(), rayon::current_thread_index());
                    busy(Duration::from_millis(3));
                    at
                },
                || (start.elapsed(), rayon::current_thread_index()),
            )
        });
        joined.push(first.0.max(second.0).as_secs_f64() * 1e6);
        joined_alone += usize::from(first.1 == second.1);
        std::thread::sleep(Duration::from_millis(20));
        let start = Instant::now();
        let starts = Mutex::new(Vec::new());
        pool.in_place_scope(|scope| {
            for _ in 0..2 {
                scope.spawn(|_| {
                    let at = (start.elapsed(), rayon::current_thread_index());
                    if let Ok(mut s) = starts.lock() {
                        s.push(at);
                    }
                    busy(Duration::from_millis(3));
                });
            }
        });
        let starts = starts.into_inner().map_err(|e| e.to_string())?;
        if let [a, b] = starts[..] {
            spawned.push(a.0.max(b.0).as_secs_f64() * 1e6);
            spawned_alone += usize::from(a.1 == b.1);
        }
    }
    println!(
        "two-thread pool idle 20 ms before: the later half of a join started {} after the call \
         ({joined_alone} of {rounds} both on one thread); the later of two tasks spawned from outside {} \
         ({spawned_alone} of {rounds} on one thread)",
        spread(joined),
        spread(spawned)
    );
    Ok(())
}

/// "median M us (90th percentile P, max X, of N)" of microsecond samples.
fn spread(mut us: Vec<f64>) -> String {
    us.sort_by(f64::total_cmp);
    let n = us.len();
    format!(
        "median {:.0} us (90th percentile {:.0}, max {:.0}, of {n})",
        us[n / 2],
        us[n * 9 / 10],
        us[n - 1]
    )
}

/// Pearson's correlation of two equally long samples (0 when either is constant).
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let (va, vb) = (
        a.iter().map(|x| (x - ma).powi(2)).sum::<f64>(),
        b.iter().map(|y| (y - mb).powi(2)).sum::<f64>(),
    );
    if va == 0.0 || vb == 0.0 {
        0.0
    } else {
        cov / (va * vb).sqrt()
    }
}

/// The clock this thread runs at now, in GHz, and the share of four additions per cycle that
/// four independent chains of additions reach at that clock. Each round of a loop runs 64
/// additions, so that the loop's own counter and branch hardly count.
#[cfg(target_arch = "x86_64")]
fn core_probe() -> Option<(f64, f64)> {
    const ROUNDS: u64 = 2_000_000;
    // One chain: each addition waits for the one before, one per cycle.
    let start = Instant::now();
    let mut x = 0u64;
    for _ in 0..ROUNDS {
        // SAFETY: additions to a register the block owns; no memory, no stack.
        unsafe {
            std::arch::asm!(".rept 64", "add {0}, 1", ".endr", inout(reg) x, options(nomem, nostack));
        }
    }
    let hz = 64.0 * ROUNDS as f64 / start.elapsed().as_secs_f64();
    // Four chains of 16 each.
    let start = Instant::now();
    let (mut a, mut b, mut c, mut d) = (0u64, 0u64, 0u64, 0u64);
    for _ in 0..ROUNDS {
        // SAFETY: as above.
        unsafe {
            std::arch::asm!(
                ".rept 16", "add {0}, 1", "add {1}, 1", "add {2}, 1", "add {3}, 1", ".endr",
                inout(reg) a, inout(reg) b, inout(reg) c, inout(reg) d,
                options(nomem, nostack),
            );
        }
    }
    let wide = 64.0 * ROUNDS as f64 / start.elapsed().as_secs_f64();
    (x == 64 * ROUNDS && a + b + c + d == 64 * ROUNDS).then(|| (hz / 1e9, wide / (4.0 * hz)))
}

#[cfg(not(target_arch = "x86_64"))]
fn core_probe() -> Option<(f64, f64)> {
    None
}
