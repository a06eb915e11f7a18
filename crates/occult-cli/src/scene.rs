//! Scenes and cameras from command-line text, through `occult-scenes`.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Result};
use occult_core::{Camera, Scene};

use crate::args::{CameraOverrides, FramesArgs, PathArg, SceneArg, ViewArg};
use crate::progress::Progress;

/// A scene built from a spec, with what the CLI reports about it.
pub struct LoadedScene {
    /// The spec as given.
    pub spec: String,
    /// The scene's name (generator or file name).
    pub name: String,
    /// The scene.
    pub scene: Arc<Scene>,
    /// The generator's (or loader's) framing camera.
    pub default_camera: Camera,
    /// What the loader skipped, one line per kind with its count.
    pub warnings: Vec<String>,
    /// Time to parse and build (generate or load), ms.
    pub build_ms: f64,
}

/// Builds the scene of a parsed spec (a generator or a file), with a spinner while it takes
/// long. The loader's warnings (one line per kind, with its count) go to stderr as
/// `warning: ...` as soon as the scene is built, and stay in [`LoadedScene::warnings`] for
/// reports.
///
/// # Errors
/// Unreadable or malformed files, generator limits.
pub fn load(arg: &SceneArg) -> Result<LoadedScene> {
    // Under `mpirun` every rank loads the scene; one that fails (a file it cannot read, memory)
    // ends every rank with one error.
    crate::ranks::agree(load_here(arg))
}

fn load_here(arg: &SceneArg) -> Result<LoadedScene> {
    let spec = arg.text.as_str();
    let start = Instant::now();
    let progress = Progress::spinner(format!("building scene {spec}"));
    let built = arg.spec.build().map_err(|e| naming(e, "scene", spec))?;
    drop(progress);
    let build_ms = start.elapsed().as_secs_f64() * 1e3;
    {
        use std::io::Write as _;
        let mut stderr = std::io::stderr().lock();
        // Under `mpirun`, rank 0 alone warns.
        for w in built.warnings.iter().filter(|_| crate::ranks::is_root()) {
            // A closed stderr loses the warnings, not the run.
            let _ = writeln!(stderr, "warning: {w}");
        }
    }
    Ok(LoadedScene {
        spec: spec.to_string(),
        name: built.name,
        scene: Arc::new(built.scene),
        default_camera: built.default_camera,
        warnings: built.warnings,
        build_ms,
    })
}

/// The cameras of a parsed path through `scene`.
///
/// # Errors
/// Degenerate views (in camera files), empty paths.
pub fn path(arg: &PathArg, scene: &LoadedScene) -> Result<Vec<Camera>> {
    let spec = arg.text.as_str();
    let cameras = arg
        .spec
        .views(&scene.scene, &scene.default_camera)
        .map_err(|e| naming(e, "camera path", spec))?;
    if cameras.is_empty() {
        bail!("camera path '{spec}' holds no camera");
    }
    Ok(cameras)
}

/// The camera named by `view` (`default`, a path, or `PATH:i`) with `overrides` applied.
///
/// # Errors
/// A degenerate camera.
pub fn camera(view: &ViewArg, overrides: &CameraOverrides, scene: &LoadedScene) -> Result<Camera> {
    let mut camera = view
        .spec
        .camera(&scene.scene, &scene.default_camera)
        .map_err(|e| naming(e, "view", &view.text))?;
    let o = overrides;
    camera.eye = o.eye.unwrap_or(camera.eye);
    camera.target = o.target.unwrap_or(camera.target);
    camera.up = o.up.unwrap_or(camera.up);
    camera.fov_y_deg = o.fov.unwrap_or(camera.fov_y_deg);
    camera.near = o.near.unwrap_or(camera.near);
    camera.far = o.far.unwrap_or(camera.far);
    camera.validate()?;
    Ok(camera)
}

/// `error` with `what 'spec'` as context, unless its message already quotes the spec.
fn naming<E: std::error::Error + Send + Sync + 'static>(error: E, what: &str, spec: &str) -> anyhow::Error {
    if error.to_string().contains(&format!("'{spec}'")) {
        anyhow::Error::new(error)
    } else {
        anyhow::Error::new(error).context(format!("{what} '{spec}'"))
    }
}

/// What reports say about a scene.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SceneSummary {
    /// The spec as given.
    pub spec: String,
    /// The scene's name.
    pub name: String,
    /// Triangle instances (the item id space).
    pub triangles: u64,
    /// Triangles stored (each mesh once).
    pub unique_triangles: u64,
    /// Nodes of the DAG.
    pub nodes: usize,
    /// Instances stored in groups.
    pub instances: u64,
    /// Approximate bytes held by the scene.
    pub memory_bytes: usize,
    /// World bounds, minimum corner.
    pub bounds_min: [f32; 3],
    /// World bounds, maximum corner.
    pub bounds_max: [f32; 3],
    /// Time to parse and build, ms.
    pub build_ms: f64,
    /// Loader warnings, one line per kind with its count (`file.obj: 12 faces with fewer than
    /// 3 corners skipped (first at line 40)`); in `info --json` as `warnings`.
    pub warnings: Vec<String>,
}

impl SceneSummary {
    /// `spec`, with the scene's name when it says something more (`model.obj (model)`).
    pub fn label(&self) -> String {
        if self.name == self.spec {
            self.spec.clone()
        } else {
            format!("{} ({})", self.spec, self.name)
        }
    }

    /// The line that opens the report of a walk along `frames` (`count` cameras):
    /// `scene S: N triangles; path P: N frames at WxH`.
    pub fn walk_line(&self, frames: &FramesArgs, count: usize) -> String {
        format!(
            "scene {}: {} triangles; path {}: {count} frames at {}x{}",
            self.label(),
            crate::output::count(self.triangles as f64),
            frames.path,
            frames.size.width,
            frames.size.height
        )
    }
}

impl LoadedScene {
    /// The summary.
    pub fn summary(&self) -> SceneSummary {
        let s = &self.scene;
        let b = s.bounds();
        SceneSummary {
            spec: self.spec.clone(),
            name: self.name.clone(),
            triangles: s.item_count(),
            unique_triangles: s.unique_triangle_count(),
            nodes: s.nodes().len(),
            instances: s.instance_count(),
            memory_bytes: s.memory_bytes(),
            bounds_min: b.min.to_array(),
            bounds_max: b.max.to_array(),
            build_ms: self.build_ms,
            warnings: self.warnings.clone(),
        }
    }
}
