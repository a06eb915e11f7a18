//! `occult shadows`: shadow volumes of a spot light counted in a stencil pass, with or without
//! culling and clamping by min/max litmaps and N-buffers (Décoret 2005 §3.3, §4.4).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use occult_core::{Camera, Vec3, View};
use occult_raster::{shade, Frame, RasterConfig, Rasterizer};
use occult_render::nbuffer::shadows::{Clamping, ShadowCasters, ShadowCounts, ShadowFrame, SpotLight};
use occult_render::{Algorithm, RenderOptions};
use serde::Serialize;

use crate::args::{parse_finite, parse_size, parse_vec3, CameraOverrides, Size};
use crate::output;
use crate::scene::{self, SceneSummary};

/// `occult shadows`.
#[derive(Debug, Args)]
pub struct ShadowsArgs {
    /// Scene spec or file (see `occult render --help`).
    #[arg(long, value_name = "SPEC")]
    pub scene: String,
    /// Camera: `default`, or camera `i` of a path as `PATH:i`.
    #[arg(long, value_name = "VIEW", default_value = "default")]
    pub view: String,
    #[command(flatten)]
    pub camera: CameraOverrides,
    /// Frame size, WxH pixels.
    #[arg(long, value_name = "WxH", default_value = "640x480", value_parser = parse_size)]
    pub size: Size,
    /// Spot light position, `x,y,z`; default: above and beside the scene.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light: Option<Vec3>,
    /// Point the light aims at, `x,y,z`; default: the scene's centre.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light_target: Option<Vec3>,
    /// Full cone angle of the light, degrees, in (0, 170]; default: holds the whole scene.
    #[arg(long, value_name = "DEG", value_parser = parse_finite)]
    pub cone: Option<f32>,
    /// Litmap side in lexels.
    #[arg(long, value_name = "N", default_value_t = 512)]
    pub litmap: u32,
    /// Triangles per caster: larger meshes are split into the leaves of a BVH (>= 1).
    #[arg(long, value_name = "N", default_value_t = 4096)]
    pub leaf: usize,
    /// Clamp the shadow volumes (`on`), draw them whole (`off`), or both, checking that the
    /// shadows are identical (`both`).
    #[arg(long, value_name = "on|off|both", default_value = "both", value_parser = ["on", "off", "both"])]
    pub clamp: String,
    /// Shaded image darkened where in shadow (PNG).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Counts and timings out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

#[derive(Serialize)]
struct Run {
    clamp: bool,
    casters: u64,
    casters_culled: u64,
    casters_clamped: u64,
    front_caps_moved: u64,
    lit_triangles: u64,
    silhouette_edges: u64,
    lookups: u64,
    litmap_points: u64,
    volume_triangles: u64,
    stencil_fragments: u64,
    stencil_updates: u64,
    shadowed_pixels: u64,
    litmap_ms: f64,
    nbuffer_ms: f64,
    volumes_ms: f64,
    stencil_ms: f64,
    total_ms: f64,
}

impl Run {
    fn new(clamp: bool, c: &ShadowCounts, total_ms: f64) -> Self {
        Self {
            clamp,
            casters: c.casters,
            casters_culled: c.casters_culled,
            casters_clamped: c.casters_clamped,
            front_caps_moved: c.front_caps_moved,
            lit_triangles: c.lit_triangles,
            silhouette_edges: c.silhouette_edges,
            lookups: c.lookups,
            litmap_points: c.litmap_points,
            volume_triangles: c.stencil.triangles_submitted,
            stencil_fragments: c.stencil.fragments,
            stencil_updates: c.stencil.updates,
            shadowed_pixels: c.shadowed_pixels,
            litmap_ms: c.litmap_ms,
            nbuffer_ms: c.nbuffer_ms,
            volumes_ms: c.volumes_ms,
            stencil_ms: c.stencil_ms,
            total_ms,
        }
    }
}

#[derive(Serialize)]
struct ShadowsOut {
    scene: SceneSummary,
    camera: Camera,
    width: u32,
    height: u32,
    light: [f32; 3],
    light_target: [f32; 3],
    cone_deg: f32,
    litmap: u32,
    casters: usize,
    runs: Vec<Run>,
    /// With `--clamp both`: pixels whose shadow state differs (always 0).
    differing_pixels: Option<u64>,
}

/// Runs the command.
pub fn run(a: ShadowsArgs) -> Result<()> {
    output::check_outputs([&Some(a.out.clone()), &a.json])?;
    if a.leaf == 0 {
        bail!("--leaf must be at least 1");
    }
    let scene = scene::load(&a.scene)?;
    let camera = scene::camera(&a.view, &a.camera, &scene)?;
    let view = View::new(camera, a.size.width, a.size.height).context("view")?;
    let mut light = SpotLight::for_bounds(&scene.scene.bounds());
    light.position = a.light.unwrap_or(light.position);
    light.target = a.light_target.unwrap_or(light.target);
    light.cone_deg = a.cone.unwrap_or(light.cone_deg);
    light.resolution = a.litmap;
    light.view()?;
    let casters = ShadowCasters::new(scene.scene.clone(), a.leaf)?;
    let mut z = Algorithm::ZBUFFER
        .build(scene.scene.clone(), &RenderOptions::default())
        .context("building zbuffer")?;
    let mut frame = Frame::new(a.size.width, a.size.height)?;
    z.render(&view, &mut frame).context("rendering the scene")?;
    let mut raster = Rasterizer::new(RasterConfig::default())?;
    let modes: &[Clamping] = match a.clamp.as_str() {
        "on" => &[Clamping::On],
        "off" => &[Clamping::Off],
        _ => &[Clamping::Off, Clamping::On],
    };
    let mut results: Vec<(ShadowFrame, f64)> = Vec::new();
    for &m in modes {
        let t = Instant::now();
        let r = casters.shadows(&mut raster, &view, &frame, &light, m)?;
        results.push((r, t.elapsed().as_secs_f64() * 1e3));
    }
    let differing = (results.len() == 2).then(|| {
        results[0]
            .0
            .shades
            .iter()
            .zip(&results[1].0.shades)
            .filter(|(x, y)| x != y)
            .count() as u64
    });
    shade(&mut frame, &scene.scene, &view);
    let mut img = frame.color_image();
    results.last().expect("one run at least").0.darken(&mut img);
    img.save_with_format(&a.out, image::ImageFormat::Png)
        .with_context(|| format!("cannot write '{}'", a.out.display()))?;

    let summary = scene.summary();
    say!(
        "scene {}: {} triangles, {} shadow casters (leaf {})",
        summary.label(),
        output::count(summary.triangles as f64),
        output::count(casters.caster_count() as f64),
        a.leaf
    );
    say!(
        "light at {:?} aimed at {:?}, cone {}°, litmaps {}x{}; frame {}x{}",
        light.position.to_array(),
        light.target.to_array(),
        light.cone_deg,
        a.litmap,
        a.litmap,
        a.size.width,
        a.size.height
    );
    let runs: Vec<Run> = modes
        .iter()
        .zip(&results)
        .map(|(&m, (r, ms))| Run::new(m == Clamping::On, &r.counts, *ms))
        .collect();
    let header = [
        "clamping",
        "casters",
        "culled",
        "clamped",
        "lookups",
        "volume tris",
        "stencil frags",
        "shadowed px",
        "total ms",
        "stencil ms",
    ];
    let rows: Vec<Vec<String>> = runs
        .iter()
        .map(|r| {
            vec![
                if r.clamp { "on" } else { "off" }.to_string(),
                output::count(r.casters as f64),
                output::count(r.casters_culled as f64),
                output::count(r.casters_clamped as f64),
                output::count(r.lookups as f64),
                output::count(r.volume_triangles as f64),
                output::count(r.stencil_fragments as f64),
                output::count(r.shadowed_pixels as f64),
                output::millis(r.total_ms),
                output::millis(r.stencil_ms),
            ]
        })
        .collect();
    say_raw!("{}", output::table(&header, &rows));
    if let Some(d) = differing {
        let (off, on) = (runs[0].stencil_fragments, runs[1].stencil_fragments);
        say!(
            "clamped fill {:.2} % of unclamped; time {:.2}x; shadows identical: {}",
            100.0 * on as f64 / off.max(1) as f64,
            runs[0].total_ms / runs[1].total_ms.max(1e-9),
            if d == 0 {
                "yes".to_string()
            } else {
                format!("NO ({d} pixels differ)")
            }
        );
    }
    say!("wrote {}", a.out.display());
    if let Some(p) = &a.json {
        let out = ShadowsOut {
            scene: summary,
            camera,
            width: a.size.width,
            height: a.size.height,
            light: light.position.to_array(),
            light_target: light.target.to_array(),
            cone_deg: light.cone_deg,
            litmap: a.litmap,
            casters: casters.caster_count(),
            runs,
            differing_pixels: differing,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    if differing.is_some_and(|d| d > 0) {
        bail!("shadows differ with and without clamping");
    }
    Ok(())
}
