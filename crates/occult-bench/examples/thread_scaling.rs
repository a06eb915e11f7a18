//! Two threads against one on the `terrain` anchor view, measured as pairs: one draw with a
//! 1-thread rasterizer, then one with a 2-thread rasterizer, alternating in one process, so
//! that both see the same machine load. Prints the minimum and median of each and the median
//! of the per-pair ratios, which drift on a noisy machine affects least.
//!
//! `cargo run --release -p occult-bench --example thread_scaling [pairs]` (default 15).
//! `... thread_scaling one-thread N` instead draws N times with one thread only, for counting
//! instructions under a profiler (`valgrind --tool=callgrind
//! --toggle-collect='occult_raster::raster::Rasterizer::draw'`).
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
    let count = |a: Option<&String>| -> Result<usize, String> {
        match a {
            Some(a) => match a.parse() {
                Ok(0) | Err(_) => Err(format!("expected a count of draws of at least 1, got `{a}`")),
                Ok(n) => Ok(n),
            },
            None => Ok(15),
        }
    };
    let pairs = count(args.get(usize::from(one_thread || contention)))?;
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
