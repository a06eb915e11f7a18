//! Shadow volumes of a spot light counted in a stencil pass, with or without culling and
//! clamping by min/max litmaps and N-buffers (Décoret 2005 §3.3, §4.4), from one view or along
//! a camera path (§4.4 measured "along recorded path"). With both modes, every frame's shadows
//! are compared pixel by pixel: clamping must not change them.
//!
//! Cost: per view, one `zbuffer` frame and one shadow pass per mode; the casters' BVH leaves
//! are built once.

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Aabb, Camera, Scene, Vec3, View};
use occult_raster::{Frame, RasterConfig, Rasterizer};
use occult_render::nbuffer::shadows::{Clamping, ShadowCasters, ShadowCounts, ShadowFrame, SpotLight};
use occult_render::{Algorithm, RenderError, RenderOptions};
use serde::Serialize;

use crate::ExperimentError;

/// The light: each field given overrides the default light of the scene
/// ([`SpotLight::for_bounds`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LightSettings {
    /// Position, world space; default above and beside the scene.
    pub position: Option<Vec3>,
    /// Point aimed at, world space; default the scene's centre.
    pub target: Option<Vec3>,
    /// Full cone angle, degrees, in (0, 170]; default holds the whole scene.
    pub cone_deg: Option<f32>,
    /// Litmap side in lexels.
    pub resolution: u32,
}

impl LightSettings {
    /// The light's own checks on the values given, before any scene is built (a light about a
    /// unit box stands in for the scene's).
    ///
    /// # Errors
    /// As [`SpotLight::view`] for the cone angle and resolution.
    pub fn check(&self) -> Result<(), RenderError> {
        let mut probe = SpotLight::for_bounds(&Aabb::new(-Vec3::ONE, Vec3::ONE));
        probe.cone_deg = self.cone_deg.unwrap_or(probe.cone_deg);
        probe.resolution = self.resolution;
        probe.view().map(|_| ())
    }

    /// The light over a scene bounded by `bounds`.
    ///
    /// # Errors
    /// As [`SpotLight::view`].
    pub fn light_for(&self, bounds: &Aabb) -> Result<SpotLight, RenderError> {
        let mut light = SpotLight::for_bounds(bounds);
        light.position = self.position.unwrap_or(light.position);
        light.target = self.target.unwrap_or(light.target);
        light.cone_deg = self.cone_deg.unwrap_or(light.cone_deg);
        light.resolution = self.resolution;
        light.view()?;
        Ok(light)
    }
}

/// Which shadow volumes are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Modes {
    /// Clamped only.
    Clamped,
    /// Whole only.
    Unclamped,
    /// Whole, then clamped, and the shadows compared.
    Both,
}

impl Modes {
    fn clampings(self) -> &'static [Clamping] {
        match self {
            Self::Clamped => &[Clamping::On],
            Self::Unclamped => &[Clamping::Off],
            Self::Both => &[Clamping::Off, Clamping::On],
        }
    }
}

/// What to run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowsConfig {
    /// The light.
    pub light: LightSettings,
    /// Triangles per caster: larger meshes are split into the leaves of a BVH (>= 1).
    pub leaf: usize,
    /// The modes run on every view.
    pub modes: Modes,
}

/// The figures of one shadow pass (one view, one mode): [`ShadowCounts`] flattened, times in ms.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ShadowRun {
    /// Whether the volumes were clamped.
    pub clamp: bool,
    /// Casters considered (with at least one lit triangle).
    pub casters: u64,
    /// Casters culled (`z_max < z_min`, or every visible point nearer than the caster).
    pub casters_culled: u64,
    /// Casters whose volume was clamped at the back or front plane.
    pub casters_clamped: u64,
    /// Of those, front caps moved onto the `z_min` plane.
    pub front_caps_moved: u64,
    /// Lit triangles of the drawn casters.
    pub lit_triangles: u64,
    /// Extruded edges (silhouette and boundary edges, after cancellation).
    pub silhouette_edges: u64,
    /// N-buffer lookups.
    pub lookups: u64,
    /// Observer pixels reprojected into the litmaps.
    pub litmap_points: u64,
    /// Shadow-volume triangles submitted to the stencil pass.
    pub volume_triangles: u64,
    /// Stencil fragments rasterized (the fill that clamping saves).
    pub stencil_fragments: u64,
    /// Stencil updates.
    pub stencil_updates: u64,
    /// Pixels shadowed.
    pub shadowed_pixels: u64,
    /// Litmaps (reprojection), ms.
    pub litmap_ms: f64,
    /// The two N-buffer builds, ms.
    pub nbuffer_ms: f64,
    /// Lookups and volume construction, ms.
    pub volumes_ms: f64,
    /// The stencil pass, ms.
    pub stencil_ms: f64,
    /// The whole pass, wall time.
    pub total_ms: f64,
}

impl ShadowRun {
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

/// One camera: its passes (one per mode, in mode order) and the pixels whose shadow differs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ShadowsFrame {
    /// The camera.
    pub camera: Camera,
    /// One pass per mode.
    pub runs: Vec<ShadowRun>,
    /// With both modes: pixels whose shadow state differs between them (should be 0).
    pub differing_pixels: Option<u64>,
}

/// What a shadows run measured.
pub struct ShadowsReport {
    /// The light used.
    pub light: SpotLight,
    /// Shadow casters (meshes, or BVH leaves of large ones).
    pub caster_count: usize,
    /// Per camera.
    pub frames: Vec<ShadowsFrame>,
    /// The last view's scene frame (unshaded) and its last pass, for a picture.
    pub last: (Frame, ShadowFrame),
}

impl ShadowsReport {
    /// Per mode, the mean of every numeric figure over the frames (the one frame's figures
    /// for a single view), as JSON objects shaped like [`ShadowRun`].
    ///
    /// # Errors
    /// Only if serialization fails, which plain numbers cannot.
    pub fn means(&self) -> Result<Vec<serde_json::Value>, serde_json::Error> {
        let modes = self.frames.first().map_or(0, |f| f.runs.len());
        (0..modes)
            .map(|k| mean_run(&self.frames.iter().map(|f| &f.runs[k]).collect::<Vec<_>>()))
            .collect()
    }

    /// With both modes: pixels whose shadow differs, over all frames (should be 0).
    pub fn differing_pixels(&self) -> Option<u64> {
        self.frames.iter().map(|f| f.differing_pixels).sum()
    }
}

/// The mean of every numeric field of `runs` (serialized), other fields from the first;
/// `Null` when there is none.
fn mean_run(runs: &[&ShadowRun]) -> Result<serde_json::Value, serde_json::Error> {
    let values: Vec<serde_json::Value> = runs.iter().map(serde_json::to_value).collect::<Result<_, _>>()?;
    let mut mean = values.first().cloned().unwrap_or_default();
    if let Some(fields) = mean.as_object_mut() {
        for (key, field) in fields.iter_mut() {
            if field.is_number() {
                let sum: f64 = values.iter().filter_map(|v| v[key].as_f64()).sum();
                *field = serde_json::json!(sum / values.len() as f64);
            }
        }
    }
    Ok(mean)
}

/// Renders every view of `views` (one at least) with `zbuffer`, then the light's shadows in
/// every mode of `config`, timing each pass and comparing the modes' shadows pixel by pixel.
///
/// # Errors
/// A bad light or leaf size, `zbuffer` failing, frame allocation.
///
/// # Panics
/// If `views` is empty.
pub fn shadows(scene: &Arc<Scene>, views: &[View], config: &ShadowsConfig) -> Result<ShadowsReport, ExperimentError> {
    let last_view = views.last().expect("one view at least");
    let light = config.light.light_for(&scene.bounds())?;
    let casters = ShadowCasters::new(Arc::clone(scene), config.leaf)?;
    let mut z = Algorithm::ZBUFFER
        .build(Arc::clone(scene), &RenderOptions::default())
        .map_err(ExperimentError::BuildZbuffer)?;
    let mut frame = Frame::new(last_view.width(), last_view.height())?;
    let mut raster = Rasterizer::new(RasterConfig::default())?;
    let modes = config.modes.clampings();
    let mut frames: Vec<ShadowsFrame> = Vec::with_capacity(views.len());
    let mut last: Option<ShadowFrame> = None;
    for (i, view) in views.iter().enumerate() {
        z.render(view, &mut frame)
            .map_err(|source| ExperimentError::RenderScene {
                camera_index: Some(i),
                source,
            })?;
        let mut results: Vec<(ShadowFrame, f64)> = Vec::new();
        for &m in modes {
            let t = Instant::now();
            let r = casters.shadows(&mut raster, view, &frame, &light, m)?;
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
        frames.push(ShadowsFrame {
            camera: *view.camera(),
            runs: modes
                .iter()
                .zip(&results)
                .map(|(&m, (r, ms))| ShadowRun::new(m == Clamping::On, &r.counts, *ms))
                .collect(),
            differing_pixels: differing,
        });
        last = results.pop().map(|(r, _)| r);
    }
    Ok(ShadowsReport {
        light,
        caster_count: casters.caster_count(),
        frames,
        last: (frame, last.expect("one mode at least")),
    })
}
