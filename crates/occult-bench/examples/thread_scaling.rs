//! Two threads against one on the `terrain` anchor view, measured as pairs: one draw with a
//! 1-thread rasterizer, then one with a 2-thread rasterizer, alternating in one process, so
//! that both see the same machine load. Prints the minimum and median of each and the median
//! of the per-pair ratios, which drift on a noisy machine affects least.
//!
//! `cargo run --release -p occult-bench --example thread_scaling [pairs]` (default 15).
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

use occult_core::glam::Affine3A;
use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mode = args.first().map(String::as_str);
    let one_thread = mode == Some("one-thread");
    let contention = mode == Some("contention");
    let machine = mode == Some("machine");
    let count = |a: Option<&String>| -> Result<usize, String> {
        match a {
            Some(a) => match a.parse() {
                Ok(0) | Err(_) => Err(format!("expected a count of draws of at least 1, got `{a}`")),
                Ok(n) => Ok(n),
            },
            None => Ok(15),
        }
    };
    let pairs = count(args.get(usize::from(one_thread || contention || machine)))?;
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
    // One timed draw into a cleared frame, in milliseconds.
    let timed = |r: &mut Rasterizer, frame: &mut Frame| {
        r.clear(frame);
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
    let mut rasterizers = [1, 2].map(raster);
    let mut frame = Frame::new(view.width(), view.height())?;
    let mut times = [Vec::new(), Vec::new()];
    for _ in 0..pairs {
        for (r, t) in rasterizers.iter_mut().zip(&mut times) {
            let r = r.as_mut().map_err(|e| e.to_string())?;
            t.push(timed(r, &mut frame).0);
        }
    }
    let ratios: Vec<f64> = times[0].iter().zip(&times[1]).map(|(a, b)| a / b).collect();
    println!(
        "1 thread: min {:.1} ms, median {:.1} ms; 2 threads: min {:.1} ms, median {:.1} ms; \
         2 over 1, median of {pairs} pairs: {:.2}x",
        min(&times[0]),
        median(&times[0]),
        min(&times[1]),
        median(&times[1]),
        median(&ratios)
    );
    Ok(())
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
