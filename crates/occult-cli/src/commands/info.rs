//! `occult info`: what a scene holds.

use anyhow::Result;
use occult_core::Camera;
use serde::Serialize;

use crate::args::InfoArgs;
use crate::output;
use crate::scene::{self, SceneSummary};

/// What `--json` holds.
#[derive(Serialize)]
struct InfoOut {
    #[serde(flatten)]
    scene: SceneSummary,
    default_camera: Camera,
}

/// Runs the command.
pub fn run(a: InfoArgs) -> Result<()> {
    let scene = scene::load(&a.scene)?;
    let s = scene.summary();
    if a.json {
        let out = InfoOut {
            scene: s,
            default_camera: scene.default_camera,
        };
        say!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let c = &scene.default_camera;
    let v = |a: [f32; 3]| format!("({}, {}, {})", a[0], a[1], a[2]);
    let rows = [
        ("scene", s.label()),
        (
            "triangles",
            format!(
                "{} (triangle instances: the item id space)",
                output::count(s.triangles as f64)
            ),
        ),
        (
            "unique triangles",
            format!(
                "{} (each mesh reachable from the root once, however often instanced)",
                output::count(s.unique_triangles as f64)
            ),
        ),
        ("nodes", output::count(s.nodes as f64)),
        ("instances", output::count(s.instances as f64)),
        ("bounds", format!("{} to {}", v(s.bounds_min), v(s.bounds_max))),
        ("memory", output::bytes(s.memory_bytes as u64)),
        ("build time", format!("{} ms", output::millis(s.build_ms))),
        (
            "default camera",
            format!(
                "eye {} target {} fov {}° near {} far {}",
                v(c.eye.to_array()),
                v(c.target.to_array()),
                c.fov_y_deg,
                c.near,
                c.far
            ),
        ),
    ];
    for (k, val) in rows {
        say!("{k:<17} {val}");
    }
    if s.warnings.is_empty() {
        say!("{:<17} none", "warnings");
    }
    for w in &s.warnings {
        say!("{:<17} {w}", "warning");
    }
    Ok(())
}
