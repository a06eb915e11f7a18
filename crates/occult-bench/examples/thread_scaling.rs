//! Two threads against one on the `terrain` anchor view, measured as pairs: one draw with a
//! 1-thread rasterizer, then one with a 2-thread rasterizer, alternating in one process, so
//! that both see the same machine load. Prints the minimum and median of each and the median
//! of the per-pair ratios, which drift on a noisy machine affects least.
//!
//! `cargo run --release -p occult-bench --example thread_scaling [pairs]` (default 15).
//! `... thread_scaling one-thread N` instead draws N times with one thread only, for counting
//! instructions under a profiler (`valgrind --tool=callgrind
//! --toggle-collect='occult_raster::raster::Rasterizer::draw'`).

use occult_core::glam::Affine3A;
use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, RasterMode, Rasterizer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let one_thread = args.first().is_some_and(|a| a == "one-thread");
    let count = |a: Option<&String>| -> Result<usize, String> {
        match a {
            Some(a) => match a.parse() {
                Ok(0) | Err(_) => Err(format!("expected a count of draws of at least 1, got `{a}`")),
                Ok(n) => Ok(n),
            },
            None => Ok(15),
        }
    };
    let pairs = count(args.get(usize::from(one_thread)))?;
    let (scene, view) = occult_bench::terrain_view();
    let mesh = scene.node(scene.root()).mesh().ok_or("terrain is one mesh")?;
    let draw = Draw {
        mesh,
        triangles: DrawTriangles::All,
        clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
        first_item: 0,
    };
    let mut rasterizers = [1, 2].map(|threads| {
        Rasterizer::new(RasterConfig {
            threads,
            ..RasterConfig::default()
        })
    });
    let mut frame = Frame::new(view.width(), view.height())?;
    if one_thread {
        let r = rasterizers[0].as_mut().map_err(|e| e.to_string())?;
        for _ in 0..pairs {
            r.clear(&mut frame);
            let start = std::time::Instant::now();
            let counts = r.draw(&view, &mut frame, std::slice::from_ref(&draw), RasterMode::Full);
            println!("1 thread: {:.1} ms, {counts:?}", start.elapsed().as_secs_f64() * 1e3);
        }
        return Ok(());
    }
    let mut times = [Vec::new(), Vec::new()];
    for _ in 0..pairs {
        for (r, t) in rasterizers.iter_mut().zip(&mut times) {
            let r = r.as_mut().map_err(|e| e.to_string())?;
            r.clear(&mut frame);
            let start = std::time::Instant::now();
            r.draw(&view, &mut frame, std::slice::from_ref(&draw), RasterMode::Full);
            t.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    let ratios: Vec<f64> = times[0].iter().zip(&times[1]).map(|(a, b)| a / b).collect();
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
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
