//! Camera paths: the sequences of views that walkthroughs, comparisons and benchmarks replay.
//!
//! A path spec (see [`parse_path`]) is one of
//!
//! | spec | views |
//! | --- | --- |
//! | `default` | the scene's single default camera |
//! | `circle:N` | `N` views on a horizontal circle around the scene's bounds, 25° above the centre, all looking at the centre, at the smallest radius where the bounding box fits the field of view from every direction round the circle ([`framing_camera`]) |
//! | `street:N` | `N` views of a walk at eye height looking ahead: along the street grid of a [`city`] (a snake over every east–west street), through the doors of a [`plant`] (a snake through unit centres on floor 0), or, for any other scene, straight across its bounds along the longer horizontal axis at eye height (1.7, or 5 % of the width for scenes under 34 units wide) above the ground: the lowest upward-facing surface below, found by casting rays down through the DAG |
//! | `flyover:N` | `N` views of one lap of an ellipse above the scene (0.1 × its width above the top), looking ahead and down (about 27°) |
//! | a file | a JSON list of views `{"eye": [x,y,z], "target": [x,y,z], "up"?, "fov_y_deg"?, "near"?, "far"?}`; missing fields come from the default camera |
//!
//! `N` is `1..=`[`MAX_VIEWS`]; a bare `circle`, `street` or `flyover` means
//! [`DEFAULT_VIEW_COUNT`] views. Views are evenly spaced by angle (circle, flyover) or by arc
//! length (street). Every view is checked with [`Camera::validate`]; near and far planes are set
//! per view to hold the whole scene ([`PathError::BadView`] should never occur for generated
//! paths; it reports bad views in files).
//!
//! Paths are saved with [`write_path_json`] (the same format, every field written), so that
//! benchmarks replay recorded walkthroughs.
//!
//! A spec is checked in two steps: [`PathSpec::parse`] checks everything that does not need the
//! scene (kind, count; a file is read and its JSON checked), so that a bad spec fails before a
//! scene is built; [`PathSpec::views`] then makes the cameras for a scene.
//!
//! A single view ([`ViewSpec`], `occult render --view`) is a path spec, meaning its first
//! camera, or `PATH:i`, camera `i` (from 0) of `PATH`: `circle:8:3`, `default:0`,
//! `cams.json:2`. A generated kind takes an index only after its count (`circle:120:3`), so that
//! `circle:3` always means the path of three views, as `--path circle:3` does, and `circle:0`
//! is refused as it is there.

use crate::generate::{city, plant};
use occult_core::{intersect_ray_triangle, Aabb, Affine3A, Camera, CoreError, NodeId, NodeKind, Ray, Scene, Vec3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Most views a path may hold.
pub const MAX_VIEWS: u32 = 1_000_000;
/// Views of a bare `circle`, `street` or `flyover`.
pub const DEFAULT_VIEW_COUNT: u32 = 120;
/// Largest camera path file read, bytes (a million views written by [`write_path_json`] take
/// about 150 MB).
pub const MAX_PATH_FILE_BYTES: u64 = 256 << 20;
/// Elevation of `circle` views above the scene's centre, degrees.
pub const CIRCLE_ELEVATION_DEG: f32 = 25.0;
/// Points along a generic `street` walk where the ground height is probed (views between them
/// interpolate linearly). All probes descend the DAG together and cost about one pass over each
/// mesh they reach, so more points cost little; fewer would cut through small bumps.
pub const GROUND_SAMPLES: u32 = 1025;
/// Triangles the ground probe may visit in all (counting a mesh pass once, and every ray
/// separately for instances whose transform tilts the rays). Past it, unprobed points take the
/// bottom of the bounds as ground. Bounds path-building time (≈ 1 s per 10^8) on huge meshes.
pub const GROUND_PROBE_BUDGET: u64 = 200_000_000;

/// What can go wrong with a camera path.
#[derive(Debug, Error)]
pub enum PathError {
    /// The spec is empty.
    #[error("empty camera path; expected default, circle:N, street:N, flyover:N or a JSON file")]
    Empty,
    /// Neither a path kind nor a file.
    #[error("unknown camera path '{0}'; expected default, circle:N, street:N, flyover:N or a JSON file (a path with '/' or '.json')")]
    Unknown(String),
    /// A view count that is not in `1..=MAX_VIEWS`.
    #[error("bad view count '{value}' in camera path '{spec}': {reason}")]
    BadCount {
        /// The whole spec.
        spec: String,
        /// The count as written.
        value: String,
        /// Why it is refused.
        reason: String,
    },
    /// A path file cannot be read or written.
    #[error("camera path file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A path file larger than [`MAX_PATH_FILE_BYTES`].
    #[error("camera path file {path} is {bytes} bytes, over the limit of {limit}")]
    FileTooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
        /// The limit.
        limit: u64,
    },
    /// Malformed JSON, or JSON that is not a list of views.
    #[error("camera path {source_name}: {message}")]
    Json {
        /// The file, or `<text>`.
        source_name: String,
        /// What serde_json reports, with line and column.
        message: String,
    },
    /// A path with no view, or more than [`MAX_VIEWS`].
    #[error("camera path {source_name} holds {count} views; expected 1..={max}", max = MAX_VIEWS)]
    ViewCount {
        /// The file, or `<text>`.
        source_name: String,
        /// Views found.
        count: usize,
    },
    /// A view index past the end of its path.
    #[error("view '{view}': index {index} is past the end of path '{path}', which has {count} views")]
    ViewIndex {
        /// The view spec as given.
        view: String,
        /// The index asked for.
        index: usize,
        /// The path part of the spec.
        path: String,
        /// Views in that path.
        count: usize,
    },
    /// A view that cannot form a camera.
    #[error("camera path view {index}: {source}")]
    BadView {
        /// Position of the view in the path (0-based).
        index: usize,
        /// Why.
        #[source]
        source: CoreError,
    },
}

/// One view as stored in a path file: `eye` and `target` required, the rest optional
/// (defaults from the scene's default camera). Vectors are `[x, y, z]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewRecord {
    /// Eye position, world space.
    pub eye: [f32; 3],
    /// Point looked at, world space.
    pub target: [f32; 3],
    /// Up direction (default: the default camera's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f32; 3]>,
    /// Vertical field of view, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_y_deg: Option<f32>,
    /// Near plane distance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near: Option<f32>,
    /// Far plane distance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub far: Option<f32>,
}

impl ViewRecord {
    /// Every field of `camera`.
    pub fn from_camera(camera: &Camera) -> Self {
        Self {
            eye: camera.eye.to_array(),
            target: camera.target.to_array(),
            up: Some(camera.up.to_array()),
            fov_y_deg: Some(camera.fov_y_deg),
            near: Some(camera.near),
            far: Some(camera.far),
        }
    }

    /// The camera, with missing fields taken from `defaults` (not validated).
    pub fn to_camera(&self, defaults: &Camera) -> Camera {
        Camera {
            eye: Vec3::from_array(self.eye),
            target: Vec3::from_array(self.target),
            up: self.up.map_or(defaults.up, Vec3::from_array),
            fov_y_deg: self.fov_y_deg.unwrap_or(defaults.fov_y_deg),
            near: self.near.unwrap_or(defaults.near),
            far: self.far.unwrap_or(defaults.far),
        }
    }
}

/// The views of path `spec` through `scene`: [`PathSpec::parse`], then [`PathSpec::views`].
///
/// # Errors
/// [`PathError::Empty`], [`PathError::Unknown`], [`PathError::BadCount`] for `N` outside
/// `1..=MAX_VIEWS`; for files [`PathError::Io`], [`PathError::FileTooLarge`],
/// [`PathError::Json`], [`PathError::ViewCount`]; [`PathError::BadView`] for a degenerate view.
pub fn parse_path(spec: &str, scene: &Scene, default_camera: &Camera) -> Result<Vec<Camera>, PathError> {
    PathSpec::parse(spec)?.views(scene, default_camera)
}

/// A path spec checked without a scene (module doc): the kind and count, or a file's views.
#[derive(Clone, Debug, PartialEq)]
pub enum PathSpec {
    /// `default`: the scene's default camera.
    Default,
    /// `circle:N`.
    Circle(u32),
    /// `street:N`.
    Street(u32),
    /// `flyover:N`.
    Flyover(u32),
    /// A JSON file of views, read; fields it leaves out come from the default camera.
    File {
        /// The file.
        path: PathBuf,
        /// Its views, 1..=[`MAX_VIEWS`] of them.
        records: Vec<ViewRecord>,
    },
}

impl PathSpec {
    /// Parses `spec`; a file is read and its JSON checked here.
    ///
    /// # Errors
    /// [`PathError::Empty`], [`PathError::Unknown`], [`PathError::BadCount`]; for files
    /// [`PathError::Io`], [`PathError::FileTooLarge`], [`PathError::Json`],
    /// [`PathError::ViewCount`].
    pub fn parse(spec: &str) -> Result<Self, PathError> {
        let spec = spec.trim();
        if spec.is_empty() {
            return Err(PathError::Empty);
        }
        let (kind, count) = match spec.split_once(':') {
            Some((k, n)) => (k, Some(n)),
            None => (spec, None),
        };
        Ok(match kind {
            "default" if count.is_none() => Self::Default,
            "circle" => Self::Circle(parse_count(spec, count)?),
            "street" => Self::Street(parse_count(spec, count)?),
            "flyover" => Self::Flyover(parse_count(spec, count)?),
            _ if looks_like_file(spec) => {
                let path = PathBuf::from(spec);
                let records = read_path_records(&path)?;
                Self::File { path, records }
            }
            _ => return Err(PathError::Unknown(spec.to_string())),
        })
    }

    /// Views the path holds (known before the scene).
    pub fn len(&self) -> usize {
        match self {
            Self::Default => 1,
            Self::Circle(n) | Self::Street(n) | Self::Flyover(n) => *n as usize,
            Self::File { records, .. } => records.len(),
        }
    }

    /// Always false: a parsed path holds at least one view.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The views through `scene`, each validated.
    ///
    /// # Errors
    /// [`PathError::BadView`] for a degenerate view.
    pub fn views(&self, scene: &Scene, default_camera: &Camera) -> Result<Vec<Camera>, PathError> {
        let views = match self {
            Self::Default => vec![*default_camera],
            Self::Circle(n) => circle(&scene.bounds(), *n, default_camera),
            Self::Street(n) => street(scene, *n, default_camera),
            Self::Flyover(n) => flyover(&scene.bounds(), *n, default_camera),
            Self::File { records, .. } => records.iter().map(|r| r.to_camera(default_camera)).collect(),
        };
        validate_views(&views)?;
        Ok(views)
    }
}

/// One camera of a path (module doc): `PATH` (its first view) or `PATH:i`.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewSpec {
    /// The path.
    pub path: PathSpec,
    /// The view's index in it, from 0, within its length.
    pub index: usize,
}

impl ViewSpec {
    /// Parses `view` (module doc).
    ///
    /// # Errors
    /// As [`PathSpec::parse`] for the path part; [`PathError::ViewIndex`] for an index past
    /// the path's end.
    pub fn parse(view: &str) -> Result<Self, PathError> {
        let view = view.trim();
        let whole = PathSpec::parse(view);
        if let Ok(path) = whole {
            return Ok(Self { path, index: 0 });
        }
        // `PATH:i`, where PATH is not a bare generated kind (whose count the index would be).
        let indexed = view.rsplit_once(':').and_then(|(prefix, i)| {
            let index = i.trim().parse::<usize>().ok()?;
            let bare_kind = ["circle", "street", "flyover"].contains(&prefix.trim());
            (!bare_kind && !i.trim().is_empty()).then_some((prefix, index))
        });
        let Some((prefix, index)) = indexed else {
            return whole.map(|path| Self { path, index: 0 });
        };
        let path = PathSpec::parse(prefix)?;
        if index >= path.len() {
            return Err(PathError::ViewIndex {
                view: view.to_string(),
                index,
                path: prefix.trim().to_string(),
                count: path.len(),
            });
        }
        Ok(Self { path, index })
    }

    /// The camera through `scene`. Not validated when it is the default camera or a file's
    /// (the caller may override fields first, then validates it); a generated path's views
    /// are.
    ///
    /// # Errors
    /// [`PathError::BadView`] for a degenerate generated view; [`PathError::ViewIndex`] for
    /// an index past the path's end (possible only for a spec not made by
    /// [`ViewSpec::parse`]).
    pub fn camera(&self, scene: &Scene, default_camera: &Camera) -> Result<Camera, PathError> {
        let camera = match &self.path {
            PathSpec::Default if self.index == 0 => Some(*default_camera),
            PathSpec::Default => None,
            PathSpec::File { records, .. } => records.get(self.index).map(|r| r.to_camera(default_camera)),
            path => path.views(scene, default_camera)?.get(self.index).copied(),
        };
        camera.ok_or_else(|| PathError::ViewIndex {
            view: format!("{:?}", self.path),
            index: self.index,
            path: format!("{:?}", self.path),
            count: self.path.len(),
        })
    }
}

fn looks_like_file(spec: &str) -> bool {
    spec.contains('/') || spec.contains('\\') || Path::new(spec).extension().is_some() || Path::new(spec).exists()
}

fn parse_count(spec: &str, count: Option<&str>) -> Result<u32, PathError> {
    let Some(text) = count else {
        return Ok(DEFAULT_VIEW_COUNT);
    };
    let bad = |reason: &str| PathError::BadCount {
        spec: spec.to_string(),
        value: text.to_string(),
        reason: reason.to_string(),
    };
    let digits: String = text.trim().chars().filter(|&c| c != '_').collect();
    if digits.is_empty() || !digits.chars().all(|c| c.is_ascii_digit()) {
        return Err(bad("not a positive integer"));
    }
    match digits.parse::<u64>() {
        Ok(0) => Err(bad("a path needs at least one view")),
        Ok(n) if n <= MAX_VIEWS as u64 => Ok(n as u32),
        _ => Err(bad(&format!("more than {MAX_VIEWS} views"))),
    }
}

fn validate_views(views: &[Camera]) -> Result<(), PathError> {
    for (index, v) in views.iter().enumerate() {
        v.validate().map_err(|source| PathError::BadView { index, source })?;
    }
    Ok(())
}

/// A camera looking at the centre of `bounds` from `direction` (towards the eye), at the
/// smallest distance where every corner of `bounds` lies within `fov_y_deg` both vertically and
/// horizontally (so any landscape aspect ratio shows it all), plus 5 %; near and far planes
/// just hold the box. Degenerate bounds are treated as a small box. Flat bounds (a plane
/// model) are never looked at edge-on: a direction within about 6° of their plane is turned
/// about 27° out of it (`out_of_flat_planes`).
pub fn framing_camera(bounds: &Aabb, direction: Vec3, fov_y_deg: f32) -> Camera {
    let frame = Framing::new(bounds, fov_y_deg);
    let back = out_of_flat_planes(bounds, direction.normalize_or(Vec3::new(0.0, 0.42, -0.9)));
    frame.camera(back, frame.distance(back))
}

/// `back` (unit) turned out of the plane of `bounds` along every axis on which they are flat
/// (under 1 % of their largest side): where its component along such an axis is under a tenth
/// of the rest, it becomes half of the rest (atan ½ ≈ 27° out of the plane).
fn out_of_flat_planes(bounds: &Aabb, back: Vec3) -> Vec3 {
    let size = bounds.size();
    let largest = size.max_element();
    if !(largest > 0.0 && largest.is_finite()) {
        return back;
    }
    let mut b = back;
    for axis in 0..3 {
        let mut rest = b;
        rest[axis] = 0.0;
        let rest = rest.length();
        if size[axis] < 0.01 * largest && b[axis].abs() < 0.1 * rest {
            b[axis] = if b[axis] < 0.0 { -0.5 * rest } else { 0.5 * rest };
        }
    }
    b.normalize_or(back)
}

/// A box to frame and a field of view.
struct Framing {
    bounds: Aabb,
    fov_y_deg: f32,
    tan: f32,
}

impl Framing {
    fn new(bounds: &Aabb, fov_y_deg: f32) -> Self {
        let fov_y_deg = fov_y_deg.clamp(1.0, 170.0);
        let centre = bounds.center();
        let pad = Vec3::splat(1e-3 * (1.0 + centre.abs().max_element()));
        let half = bounds.half_extent().max(pad);
        Self {
            bounds: Aabb::new(centre - half, centre + half),
            fov_y_deg,
            tan: (0.5 * fov_y_deg).to_radians().tan(),
        }
    }

    /// Right and up axes of a camera whose `back` axis (target to eye) is given.
    fn axes(back: Vec3) -> (Vec3, Vec3) {
        let right = Vec3::Y.cross(back).normalize_or(Vec3::X);
        (right, back.cross(right))
    }

    /// Smallest eye distance from the centre along `back` that shows every corner, plus 5 %.
    fn distance(&self, back: Vec3) -> f32 {
        let (right, up) = Self::axes(back);
        let c = self.bounds.center();
        let fit = |p: &Vec3| {
            let q = *p - c;
            q.dot(back) + q.dot(right).abs().max(q.dot(up).abs()) / self.tan
        };
        1.05 * self.bounds.corners().iter().map(fit).fold(0.0f32, f32::max)
    }

    /// The camera at `distance` along `back`, near and far planes holding the box.
    fn camera(&self, back: Vec3, distance: f32) -> Camera {
        let c = self.bounds.center();
        let depths = self.bounds.corners().map(|p| (c - p).dot(back) + distance);
        let nearest = depths.iter().copied().fold(f32::INFINITY, f32::min);
        let farthest = depths.iter().copied().fold(0.0f32, f32::max);
        let near = (0.5 * nearest).max(distance * 1e-5);
        let far = (farthest * 1.05).max(near * 10.0);
        Camera {
            eye: c + back * distance,
            target: c,
            up: Vec3::Y,
            fov_y_deg: self.fov_y_deg,
            near,
            far,
        }
    }
}

/// The direction of a `circle` view at `angle` radians (0 is the −z side).
fn circle_direction(angle: f32) -> Vec3 {
    let el = CIRCLE_ELEVATION_DEG.to_radians();
    Vec3::new(angle.sin() * el.cos(), el.sin(), -angle.cos() * el.cos())
}

/// `count` views on a horizontal circle around `bounds` (see the module doc), starting on the
/// −z side and turning counter-clockwise seen from above; fov from `base`. The radius is the
/// largest framing distance over 64 directions round the circle, so it depends on the scene
/// only, not on `count`.
pub fn circle(bounds: &Aabb, count: u32, base: &Camera) -> Vec<Camera> {
    let frame = Framing::new(bounds, base.fov_y_deg);
    let angle = |k: u32, n: u32| std::f32::consts::TAU * k as f32 / n as f32;
    let distance = (0..64)
        .map(|k| frame.distance(circle_direction(angle(k, 64))))
        .fold(0.0f32, f32::max);
    (0..count)
        .map(|k| frame.camera(circle_direction(angle(k, count)), distance))
        .collect()
}

/// `count` views of one lap of an ellipse above `bounds`, looking ahead and down.
pub fn flyover(bounds: &Aabb, count: u32, base: &Camera) -> Vec<Camera> {
    let c = bounds.center();
    let size = bounds.size();
    let width = size.x.max(size.z).max(size.y).max(1e-3);
    let (a, b) = ((0.35 * size.x).max(0.05 * width), (0.35 * size.z).max(0.05 * width));
    let altitude = bounds.max.y + 0.1 * width;
    let drop = altitude - c.y;
    (0..count)
        .map(|k| {
            let theta = std::f32::consts::TAU * k as f32 / count as f32;
            let (sin, cos) = theta.sin_cos();
            let eye = Vec3::new(c.x + a * cos, altitude, c.z + b * sin);
            let ahead = Vec3::new(-a * sin, 0.0, b * cos).normalize_or(Vec3::X);
            let target = Vec3::new(eye.x + ahead.x * 2.0 * drop, c.y, eye.z + ahead.z * 2.0 * drop);
            with_planes(bounds, eye, target, base.fov_y_deg, drop * 1e-3)
        })
        .collect()
}

/// A camera `eye → target`, up +y, whose far plane holds all of `bounds` and whose near plane
/// is `near` (at least far·10⁻⁷).
fn with_planes(bounds: &Aabb, eye: Vec3, target: Vec3, fov_y_deg: f32, near: f32) -> Camera {
    let far = bounds.corners().iter().map(|c| c.distance(eye)).fold(0.0f32, f32::max) * 1.05;
    let near = near.max(far * 1e-7).max(f32::MIN_POSITIVE);
    Camera {
        eye,
        target,
        up: Vec3::Y,
        fov_y_deg: fov_y_deg.clamp(1.0, 170.0),
        near,
        far: far.max(near * 10.0),
    }
}

/// `count` views of a walk at eye height (see the module doc).
pub fn street(scene: &Scene, count: u32, base: &Camera) -> Vec<Camera> {
    let bounds = scene.bounds();
    let root = scene.node(scene.root()).name();
    let (route, heights, eye_height) = if root == city::ROOT_NAME {
        (city_route(&bounds), None, city::EYE_HEIGHT)
    } else if root == plant::ROOT_NAME {
        (plant_route(&bounds), None, plant::EYE_HEIGHT)
    } else {
        let size = bounds.size();
        let eye_height = (0.05 * size.x.max(size.z)).clamp(1e-3, 1.7);
        let route = straight_route(&bounds);
        let heights = ground_profile(scene, &route);
        (route, Some(heights), eye_height)
    };
    let length = route.length();
    let look = (0.25 * length).min(10.0 * eye_height / 1.7);
    let span = length - look;
    (0..count)
        .map(|k| {
            let s = if count > 1 {
                span * k as f32 / (count - 1) as f32
            } else {
                0.0
            };
            let lift = |s: f32| {
                let ground = heights
                    .as_ref()
                    .map_or(0.0, |h| h.at(s / length.max(f32::MIN_POSITIVE)));
                Vec3::Y * (ground + eye_height)
            };
            let eye = route.at(s) + lift(s);
            let target = route.at(s + look) + lift(s + look);
            with_planes(&bounds, eye, target, base.fov_y_deg, 0.05 * eye_height)
        })
        .collect()
}

/// A polyline parameterised by arc length.
struct Route {
    points: Vec<Vec3>,
    cumulative: Vec<f32>,
}

impl Route {
    fn new(points: Vec<Vec3>) -> Self {
        let mut cumulative = Vec::with_capacity(points.len());
        let mut total = 0.0;
        for (k, p) in points.iter().enumerate() {
            if k > 0 {
                total += p.distance(points[k - 1]);
            }
            cumulative.push(total);
        }
        Self { points, cumulative }
    }

    fn length(&self) -> f32 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// The point at arc length `s` (clamped to the route).
    fn at(&self, s: f32) -> Vec3 {
        let k = self
            .cumulative
            .partition_point(|&c| c < s)
            .clamp(1, self.points.len().max(2) - 1);
        if self.points.len() < 2 {
            return self.points.first().copied().unwrap_or(Vec3::ZERO);
        }
        let (s0, s1) = (self.cumulative[k - 1], self.cumulative[k]);
        let t = if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.points[k - 1].lerp(self.points[k], t)
    }
}

/// Snake over every east–west street of a city (`y = 0`), joined along the edge streets.
fn city_route(bounds: &Aabb) -> Route {
    let pitch = city::BLOCK_PITCH;
    // Clamped: a loaded file whose root happens to be named "city" must not allocate absurdly.
    let blocks = (bounds.size().x / pitch).round().clamp(1.0, city::MAX_BLOCKS as f32) as u32;
    let c = bounds.center();
    let h = 0.5 * blocks as f32 * pitch;
    let mut points = Vec::with_capacity(2 * blocks as usize + 2);
    for k in 0..=blocks {
        let z = c.z - h + k as f32 * pitch;
        let (x0, x1) = if k % 2 == 0 {
            (c.x - h, c.x + h)
        } else {
            (c.x + h, c.x - h)
        };
        points.push(Vec3::new(x0, 0.0, z));
        points.push(Vec3::new(x1, 0.0, z));
    }
    Route::new(points)
}

/// Snake through the unit centres of a plant's floor 0, turning through doors.
fn plant_route(bounds: &Aabb) -> Route {
    let unit = plant::UNIT_SIZE;
    let units = ((bounds.size().x - plant::WALL_THICKNESS) / unit)
        .round()
        .clamp(1.0, plant::MAX_UNITS as f32) as u32;
    let c = bounds.center();
    let h = 0.5 * units as f32 * unit;
    let (west, east) = (c.x - h + 0.5 * unit, c.x + h - 0.5 * unit);
    let mut points = Vec::with_capacity(2 * units as usize);
    for j in 0..units {
        let z = c.z - h + (j as f32 + 0.5) * unit;
        let (mut from, mut to) = if j % 2 == 0 { (west, east) } else { (east, west) };
        // Start and end near the hall's walls, so that a one-unit plant still has a walk.
        if j == 0 {
            from = if j % 2 == 0 { c.x - h + 1.0 } else { c.x + h - 1.0 };
        }
        if j == units - 1 {
            to = if j % 2 == 0 { c.x + h - 1.0 } else { c.x - h + 1.0 };
        }
        points.push(Vec3::new(from, 0.0, z));
        points.push(Vec3::new(to, 0.0, z));
    }
    Route::new(points)
}

/// Across the bounds along the longer horizontal axis through the centre, 5 % in from each
/// edge, at height 0 (the ground profile adds the height).
fn straight_route(bounds: &Aabb) -> Route {
    let c = bounds.center();
    let size = bounds.size();
    let length = size.x.max(size.z).max(size.y).max(1e-3 * (1.0 + c.abs().max_element()));
    let axis = if size.z > size.x { Vec3::Z } else { Vec3::X };
    let flat = Vec3::new(c.x, 0.0, c.z);
    Route::new(vec![flat - axis * (0.45 * length), flat + axis * (0.45 * length)])
}

/// Ground heights sampled evenly along a route, linearly interpolated.
struct Profile(Vec<f32>);

impl Profile {
    /// Height at fraction `t ∈ [0, 1]` of the route.
    fn at(&self, t: f32) -> f32 {
        let n = self.0.len();
        if n == 1 {
            return self.0[0];
        }
        let f = t.clamp(0.0, 1.0) * (n - 1) as f32;
        let k = (f as usize).min(n - 2);
        self.0[k] + (self.0[k + 1] - self.0[k]) * (f - k as f32)
    }
}

/// The lowest surface below [`GROUND_SAMPLES`] evenly spaced points of `route` (the bottom of
/// the bounds where a ray finds nothing).
fn ground_profile(scene: &Scene, route: &Route) -> Profile {
    let bounds = scene.bounds();
    let length = route.length();
    let points: Vec<Vec3> = (0..GROUND_SAMPLES)
        .map(|k| route.at(length * k as f32 / (GROUND_SAMPLES - 1) as f32))
        .collect();
    let mut probe = GroundProbe {
        scene,
        budget: GROUND_PROBE_BUDGET,
    };
    Profile(
        probe
            .lowest_surfaces(&points)
            .into_iter()
            .map(|h| h.unwrap_or(bounds.min.y))
            .collect(),
    )
}

/// Casts vertical rays down through the scene DAG, all at once, pruned by node bounds.
///
/// "Ground" is the lowest surface that faces up (its front towards the sky), so that a walk
/// stands on floors, not under the bottom faces of slabs; where a ray meets no such surface
/// (meshes wound inconsistently), the lowest surface of any facing.
struct GroundProbe<'a> {
    scene: &'a Scene,
    budget: u64,
}

/// Per ray: the largest hit parameter on an upward-facing surface, and on any surface.
struct Hits {
    up: Vec<f32>,
    any: Vec<f32>,
}

impl Hits {
    fn record(&mut self, k: usize, t: f32, faces_up: bool) {
        self.any[k] = self.any[k].max(t);
        if faces_up {
            self.up[k] = self.up[k].max(t);
        }
    }
}

impl GroundProbe<'_> {
    /// Height of the ground below each point (see the type doc), if any surface is there.
    fn lowest_surfaces(&mut self, points: &[Vec3]) -> Vec<Option<f32>> {
        let b = self.scene.bounds();
        let top = b.max.y + 1.0 + 1e-3 * b.max.y.abs();
        let t_max = top - b.min.y + 1.0;
        let rays: Vec<(usize, Ray)> = points
            .iter()
            .enumerate()
            .map(|(k, p)| {
                (
                    k,
                    Ray {
                        origin: Vec3::new(p.x, top, p.z),
                        direction: Vec3::NEG_Y,
                        t_min: 0.0,
                        t_max,
                    },
                )
            })
            .collect();
        let mut hits = Hits {
            up: vec![f32::NEG_INFINITY; points.len()],
            any: vec![f32::NEG_INFINITY; points.len()],
        };
        self.visit(self.scene.root(), &rays, false, &mut hits);
        hits.up
            .iter()
            .zip(&hits.any)
            .map(|(&up, &any)| {
                let t = if up > f32::NEG_INFINITY { up } else { any };
                (t > f32::NEG_INFINITY).then_some(top - t)
            })
            .collect()
    }

    /// Records the hits of the rays below node `id`. The rays are in the node's space (affine
    /// maps keep the parameter `t`) and already meet its bounds; `mirrored` says whether the
    /// node's placement reverses winding (negative determinant).
    fn visit(&mut self, id: NodeId, rays: &[(usize, Ray)], mirrored: bool, hits: &mut Hits) {
        match self.scene.node(id).kind() {
            NodeKind::Mesh(mesh) => self.hit_mesh(mesh, rays, mirrored, hits),
            NodeKind::Group(instances) => {
                for inst in instances {
                    let child = self.scene.node(inst.child);
                    // Test in the parent's space first: only rays that can reach the child are moved.
                    // Pruning by the upward hits alone keeps the fallback to any hit exact.
                    let bounds = child.bounds().transformed(&inst.parent_from_child);
                    let child_from_parent: Affine3A = inst.parent_from_child.inverse();
                    let local: Vec<(usize, Ray)> = rays
                        .iter()
                        .filter(|(k, r)| r.intersect_aabb(&bounds).is_some_and(|(_, exit)| exit > hits.up[*k]))
                        .map(|&(k, r)| {
                            let origin = child_from_parent.transform_point3(r.origin);
                            (
                                k,
                                Ray {
                                    origin,
                                    direction: child_from_parent.transform_vector3(r.direction),
                                    ..r
                                },
                            )
                        })
                        .collect();
                    if !local.is_empty() && self.budget > 0 {
                        let flips = inst.parent_from_child.matrix3.determinant() < 0.0;
                        self.visit(inst.child, &local, mirrored != flips, hits);
                    }
                }
            }
        }
    }

    fn hit_mesh(&mut self, mesh: &occult_core::Mesh, rays: &[(usize, Ray)], mirrored: bool, hits: &mut Hits) {
        // A triangle faces up (towards the ray's origin) when its front normal opposes the ray.
        let faces_up = |r: &Ray, [a, b, c]: [Vec3; 3]| ((b - a).cross(c - a).dot(r.direction) < 0.0) != mirrored;
        let vertical = rays.iter().all(|(_, r)| r.direction.x == 0.0 && r.direction.z == 0.0);
        if !vertical {
            // Rays tilted by a general transform: brute force, within the budget.
            for &(k, ref r) in rays {
                self.budget = self.budget.saturating_sub(mesh.triangle_count() as u64);
                for t in 0..mesh.triangle_count() {
                    let [a, b, c] = mesh.triangle_positions(t);
                    if let Some(hit) = intersect_ray_triangle(r, a, b, c) {
                        hits.record(k, hit.t, faces_up(r, [a, b, c]));
                    }
                }
            }
            return;
        }
        // Vertical rays: a triangle can only be hit by rays whose (x, z) lies in its box. Sort the
        // rays by x and visit, per triangle, those in its x range: one pass over the mesh.
        let mut sorted: Vec<&(usize, Ray)> = rays.iter().collect();
        sorted.sort_by(|a, b| a.1.origin.x.total_cmp(&b.1.origin.x));
        self.budget = self.budget.saturating_sub(mesh.triangle_count() as u64);
        for t in 0..mesh.triangle_count() {
            let [a, b, c] = mesh.triangle_positions(t);
            let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
            let first = sorted.partition_point(|r| r.1.origin.x < lo.x);
            for &&(k, ref r) in sorted[first..].iter().take_while(|r| r.1.origin.x <= hi.x) {
                if r.origin.z < lo.z || r.origin.z > hi.z {
                    continue;
                }
                if let Some(hit) = intersect_ray_triangle(r, a, b, c) {
                    hits.record(k, hit.t, faces_up(r, [a, b, c]));
                }
            }
        }
    }
}

/// `views` as JSON, the format [`parse_path`] reads: a list with one view per line, every field
/// written (about 150 bytes a view, so [`MAX_VIEWS`] views stay under [`MAX_PATH_FILE_BYTES`]).
pub fn path_to_json(views: &[Camera]) -> String {
    let mut out = String::with_capacity(2 + views.len() * 160);
    out.push('[');
    for (k, v) in views.iter().enumerate() {
        out.push_str(if k == 0 { "\n  " } else { ",\n  " });
        // Serializing a plain struct of floats and arrays cannot fail (no maps, no custom
        // serializers); a non-finite float is written as `null` and refused when read back.
        out.push_str(&serde_json::to_string(&ViewRecord::from_camera(v)).unwrap_or_else(|_| "null".to_string()));
    }
    out.push_str("\n]\n");
    out
}

/// Parses a JSON list of views (see [`ViewRecord`]); `source_name` names the text in errors.
///
/// # Errors
/// [`PathError::Json`] for malformed JSON or unknown fields, [`PathError::ViewCount`] for an
/// empty list or more than [`MAX_VIEWS`], [`PathError::BadView`] for a degenerate view.
pub fn path_from_json(text: &str, source_name: &str, defaults: &Camera) -> Result<Vec<Camera>, PathError> {
    let views: Vec<Camera> = records_from_json(text, source_name)?
        .iter()
        .map(|r| r.to_camera(defaults))
        .collect();
    validate_views(&views)?;
    Ok(views)
}

/// The views of a JSON list, unchecked as cameras.
fn records_from_json(text: &str, source_name: &str) -> Result<Vec<ViewRecord>, PathError> {
    let records: Vec<ViewRecord> = serde_json::from_str(text).map_err(|e| PathError::Json {
        source_name: source_name.to_string(),
        message: e.to_string(),
    })?;
    if records.is_empty() || records.len() > MAX_VIEWS as usize {
        return Err(PathError::ViewCount {
            source_name: source_name.to_string(),
            count: records.len(),
        });
    }
    Ok(records)
}

/// Reads a JSON path file (at most [`MAX_PATH_FILE_BYTES`]).
///
/// # Errors
/// [`PathError::Io`], [`PathError::FileTooLarge`], and those of [`path_from_json`].
pub fn read_path_json(path: &Path, defaults: &Camera) -> Result<Vec<Camera>, PathError> {
    let views: Vec<Camera> = read_path_records(path)?.iter().map(|r| r.to_camera(defaults)).collect();
    validate_views(&views)?;
    Ok(views)
}

/// The views of a JSON path file, unchecked as cameras.
fn read_path_records(path: &Path) -> Result<Vec<ViewRecord>, PathError> {
    let io = |source| PathError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = std::fs::metadata(path).map_err(io)?.len();
    if bytes > MAX_PATH_FILE_BYTES {
        return Err(PathError::FileTooLarge {
            path: path.to_path_buf(),
            bytes,
            limit: MAX_PATH_FILE_BYTES,
        });
    }
    let text = std::fs::read_to_string(path).map_err(io)?;
    records_from_json(&text, &path.display().to_string())
}

/// Writes `views` to `path` as JSON ([`path_to_json`]).
///
/// # Errors
/// [`PathError::Io`] when the file cannot be written.
pub fn write_path_json(path: &Path, views: &[Camera]) -> Result<(), PathError> {
    std::fs::write(path, path_to_json(views)).map_err(|source| PathError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_parse_strictly() {
        assert_eq!(
            parse_count("circle", None).expect("a bare path takes the default count"),
            DEFAULT_VIEW_COUNT
        );
        assert_eq!(
            parse_count("circle:1_000", Some("1_000")).expect("an underscored count parses"),
            1000
        );
        for bad in ["0", "-1", "", "1.5", "x", "1000001", "99999999999999999999999"] {
            assert!(parse_count("circle", Some(bad)).is_err(), "{bad}");
        }
    }

    #[test]
    fn route_is_parameterised_by_arc_length() {
        let r = Route::new(vec![Vec3::ZERO, Vec3::X * 3.0, Vec3::new(3.0, 0.0, 4.0)]);
        assert_eq!(r.length(), 7.0);
        assert_eq!(r.at(0.0), Vec3::ZERO);
        assert_eq!(r.at(5.0), Vec3::new(3.0, 0.0, 2.0));
        assert_eq!(r.at(99.0), Vec3::new(3.0, 0.0, 4.0));
        assert_eq!(r.at(-1.0), Vec3::ZERO);
    }

    #[test]
    fn flat_bounds_are_not_framed_edge_on() {
        let front = Vec3::new(0.0, 0.42, -0.9);
        // A triangle in the yz plane: the default direction lies in its plane.
        let yz = Aabb::new(Vec3::new(0.0, -1.0, -1.0), Vec3::new(0.0, 1.0, 1.0));
        let c = framing_camera(&yz, front, 60.0);
        c.validate().expect("framing a flat box gives a valid camera");
        let d = c.direction();
        assert!(d.x.abs() > 0.4, "looks along {d}, within its plane");
        // Flat in y (ground) and z (a wall facing the camera): the direction is kept.
        for flat in [
            Aabb::new(Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0)),
            Aabb::new(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0)),
            Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)),
        ] {
            let c = framing_camera(&flat, front, 60.0);
            assert!((c.direction() + front.normalize()).length() < 1e-5, "{flat:?}");
        }
    }

    #[test]
    fn views_take_an_index_only_where_it_cannot_be_a_count() {
        let v = |s: &str| ViewSpec::parse(s);
        assert_eq!(
            v("circle:8").expect("a count alone parses"),
            ViewSpec {
                path: PathSpec::Circle(8),
                index: 0
            }
        );
        assert_eq!(
            v("circle:8:3").expect("a count and an index below it parse"),
            ViewSpec {
                path: PathSpec::Circle(8),
                index: 3
            }
        );
        assert_eq!(
            v("default").expect("the default path parses"),
            ViewSpec {
                path: PathSpec::Default,
                index: 0
            }
        );
        assert_eq!(
            v("default:0").expect("index 0 of the default path parses"),
            ViewSpec {
                path: PathSpec::Default,
                index: 0
            }
        );
        assert_eq!(
            v("circle").expect("a bare circle parses").path,
            PathSpec::Circle(DEFAULT_VIEW_COUNT)
        );
        // As --path circle:0 is refused, so is --view circle:0 (not camera 0 of `circle`).
        assert!(matches!(v("circle:0"), Err(PathError::BadCount { .. })));
        assert!(matches!(v("street:0"), Err(PathError::BadCount { .. })));
        let e = v("circle:8:8").unwrap_err();
        assert!(matches!(e, PathError::ViewIndex { index: 8, count: 8, .. }), "{e}");
        assert!(matches!(v("default:1"), Err(PathError::ViewIndex { .. })));
        assert!(matches!(v("circle:x"), Err(PathError::BadCount { .. })));
        assert!(matches!(v("spiral:3"), Err(PathError::Unknown(_))));
        assert!(matches!(v("no/such.json:2"), Err(PathError::Io { .. })));
    }

    #[test]
    fn framing_of_a_point_is_not_degenerate() {
        let c = framing_camera(&Aabb::new(Vec3::ONE, Vec3::ONE), Vec3::Y + Vec3::Z, 60.0);
        c.validate().expect("framing a point gives a valid camera");
    }

    #[test]
    fn profile_interpolates() {
        let p = Profile(vec![0.0, 2.0, 4.0]);
        assert_eq!(p.at(0.25), 1.0);
        assert_eq!(p.at(1.0), 4.0);
        assert_eq!(Profile(vec![3.0]).at(0.7), 3.0);
    }
}
