//! `occult particles`: particle culling with an N-buffer (Décoret 2005 §3.2): a scene drawn,
//! then many screen-aligned sprites among its geometry, each tested in constant time against
//! an N-buffer of the scene's depth (`--cull on`) or all drawn (`--cull off`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use occult_core::{Camera, View};
use occult_harness::particles::{particles, ParticlesConfig};
use occult_render::nbuffer::particles::{MAX_PARTICLES, MAX_SPRITE_SIZE};
use serde::Serialize;

use crate::args::{parse_scene, parse_size, CameraArgs, SceneArg, Size};
use crate::output;
use crate::scene::{self, SceneSummary};

/// `occult particles`.
#[derive(Debug, Args)]
pub struct ParticlesArgs {
    /// Scene spec or file (see `occult render --help`); `city` or `forest` place the sprites
    /// among buildings or trees.
    #[arg(long, value_name = "SPEC", value_parser = parse_scene)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Frame size, WxH pixels.
    #[arg(long, value_name = "WxH", default_value = "640x480", value_parser = parse_size)]
    pub size: Size,
    /// Number of particles.
    #[arg(long, value_name = "N", default_value_t = 1_000_000)]
    pub count: usize,
    /// Sprite sides in pixels: `1-N` (uniform in 1..=N, N <= 64) or `pow2` / `pow2-N` (the
    /// powers of two up to N: one N-buffer lookup each).
    #[arg(long, value_name = "SIZES", default_value = "1-64", value_parser = parse_sizes)]
    pub sizes: SpriteSizes,
    /// Cull sprites against the N-buffer (`on`) or draw them all (`off`).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_on_off, action = clap::ArgAction::Set)]
    pub cull: bool,
    /// Test the four-lookup sprites in one batched N-buffer call (`on`) or one call each
    /// (`off`: same results; for measuring the batch).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_on_off, action = clap::ArgAction::Set)]
    pub batch: bool,
    /// Share of the scene's height (from the ground) the particles fill, in (0, 1].
    #[arg(long, value_name = "F", default_value_t = 0.3, allow_negative_numbers = true)]
    pub fill: f32,
    /// Seed of the particle placement.
    #[arg(long, value_name = "N", default_value_t = 9)]
    pub seed: u64,
    /// Color image out (PNG).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Counts and timings out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// Sprite sides: the largest, and whether only powers of two.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpriteSizes {
    /// Largest side in pixels.
    pub max: u32,
    /// Only powers of two.
    pub power_of_two: bool,
}

/// Parses `1-N`, `pow2` or `pow2-N`.
pub fn parse_sizes(s: &str) -> Result<SpriteSizes, String> {
    let s = s.trim();
    let (power_of_two, max) = if s == "pow2" {
        (true, Some(MAX_SPRITE_SIZE.to_string()))
    } else if let Some(n) = s.strip_prefix("pow2-") {
        (true, Some(n.to_string()))
    } else if let Some(n) = s.strip_prefix("1-") {
        (false, Some(n.to_string()))
    } else {
        (false, None)
    };
    let max: u32 = max
        .and_then(|n| n.parse().ok())
        .ok_or_else(|| format!("'{s}' is not 1-N, pow2 or pow2-N"))?;
    if !(1..=MAX_SPRITE_SIZE).contains(&max) {
        return Err(format!("largest sprite side {max} is not in 1..={MAX_SPRITE_SIZE}"));
    }
    Ok(SpriteSizes { max, power_of_two })
}

/// Parses `on` or `off`.
pub fn parse_on_off(s: &str) -> Result<bool, String> {
    match s {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("'{s}' is not on or off")),
    }
}

#[derive(Serialize)]
struct ParticlesOut {
    scene: SceneSummary,
    camera: Camera,
    width: u32,
    height: u32,
    count: usize,
    max_sprite: u32,
    power_of_two: bool,
    cull: bool,
    batch: bool,
    sprites_in_view: u64,
    sprites_culled: u64,
    lookups: u64,
    single_lookup_tests: u64,
    triangles_rasterized: u64,
    fragments_written: u64,
    nbuffer_levels: u32,
    /// N-buffer build, ms (0 without culling).
    nbuffer_ms: f64,
    /// Culling and drawing the sprites, ms (N-buffer build excluded).
    draw_ms: f64,
    /// The N-buffer tests alone, ms (part of `draw_ms`).
    cull_ms: f64,
    /// Both, ms.
    total_ms: f64,
    scene_ms: f64,
}

/// Runs the command.
pub fn run(a: ParticlesArgs) -> Result<()> {
    output::check_outputs([&Some(a.out.clone()), &a.json])?;
    if a.count > MAX_PARTICLES {
        bail!("{} particles is more than {MAX_PARTICLES}", a.count);
    }
    if !(a.fill > 0.0 && a.fill <= 1.0) {
        bail!("--fill {} is not in (0, 1]", a.fill);
    }
    a.camera.overrides.check()?;
    let scene = scene::load(&a.scene)?;
    let camera = scene::camera(&a.camera.view, &a.camera.overrides, &scene)?;
    let view = View::new(camera, a.size.width, a.size.height).context("view")?;
    let config = ParticlesConfig {
        count: a.count,
        max_sprite: a.sizes.max,
        power_of_two: a.sizes.power_of_two,
        cull: a.cull,
        batch: a.batch,
        fill: a.fill,
        seed: a.seed,
    };
    let run = particles(&scene.scene, &view, &config)?;
    let c = &run.counts;
    let (nbuffer_ms, draw_ms, cull_ms, scene_ms) = (run.nbuffer_ms, run.draw_ms, run.cull_ms, run.scene_ms);
    output::write_color_png(&run.frame, &a.out)?;

    let summary = scene.summary();
    say!(
        "scene {}: {} triangles",
        summary.label(),
        output::count(summary.triangles as f64)
    );
    say!(
        "{} particles, sides {}{}, at {}x{}, culling {}",
        output::count(a.count as f64),
        if a.sizes.power_of_two {
            "powers of two up to "
        } else {
            "1.."
        },
        a.sizes.max,
        a.size.width,
        a.size.height,
        if a.cull { "on" } else { "off" }
    );
    let pct = |n: u64| 100.0 * n as f64 / c.sprites_in_view.max(1) as f64;
    say!(
        "  {:<24} {}",
        "sprites in view",
        output::count(c.sprites_in_view as f64)
    );
    say!(
        "  {:<24} {} ({:.1} %)",
        "sprites culled",
        output::count(c.sprites_culled as f64),
        pct(c.sprites_culled)
    );
    say!("  {:<24} {}", "N-buffer lookups", output::count(c.lookups as f64));
    say!(
        "  {:<24} {}",
        "single-lookup tests",
        output::count(c.single_lookup_tests as f64)
    );
    say!(
        "  {:<24} {}",
        "triangles rasterized",
        output::count(c.raster.triangles_rasterized as f64)
    );
    say!(
        "  {:<24} {}",
        "fragments written",
        output::count(c.raster.fragments_written as f64)
    );
    say!(
        "  {:<24} {} ms (N-buffer {} ms, {} levels; cull and draw {} ms, of which tests {} ms{}); scene {} ms",
        "time",
        output::millis(nbuffer_ms + draw_ms),
        output::millis(nbuffer_ms),
        run.nbuffer_levels,
        output::millis(draw_ms),
        output::millis(cull_ms),
        if a.batch { ", batched" } else { ", one call each" },
        output::millis(scene_ms)
    );
    say!("wrote {}", a.out.display());
    if let Some(p) = &a.json {
        let out = ParticlesOut {
            scene: summary,
            camera,
            width: a.size.width,
            height: a.size.height,
            count: a.count,
            max_sprite: a.sizes.max,
            power_of_two: a.sizes.power_of_two,
            cull: a.cull,
            batch: a.batch,
            sprites_in_view: c.sprites_in_view,
            sprites_culled: c.sprites_culled,
            lookups: c.lookups,
            single_lookup_tests: c.single_lookup_tests,
            triangles_rasterized: c.raster.triangles_rasterized,
            fragments_written: c.raster.fragments_written,
            nbuffer_levels: run.nbuffer_levels,
            nbuffer_ms,
            draw_ms,
            cull_ms,
            total_ms: nbuffer_ms + draw_ms,
            scene_ms,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sprite_sizes() {
        assert_eq!(
            parse_sizes("1-64"),
            Ok(SpriteSizes {
                max: 64,
                power_of_two: false
            })
        );
        assert_eq!(
            parse_sizes("pow2"),
            Ok(SpriteSizes {
                max: 64,
                power_of_two: true
            })
        );
        assert_eq!(
            parse_sizes("pow2-16"),
            Ok(SpriteSizes {
                max: 16,
                power_of_two: true
            })
        );
        for bad in ["", "64", "1-0", "1-65", "pow2-0", "pow3", "1-x", "2-64"] {
            assert!(parse_sizes(bad).is_err(), "{bad}");
        }
        assert!(parse_on_off("yes").is_err());
    }
}
