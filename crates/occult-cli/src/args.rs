//! The command line: clap definitions and the value parsers that turn text into checked values.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use occult_core::{Camera, CoreError, Vec3};
use occult_render::{AlgoSpec, Algorithm};
use occult_scenes::{PathSpec, SceneSpec, ViewSpec};

/// Render, walk and compare visibility algorithms on huge triangle scenes.
#[derive(Debug, Parser)]
#[command(name = "occult", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    /// Worker threads for everything (scene building and rasterizing); default: all cores.
    #[arg(long, global = true, value_name = "N", value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Under `mpirun` (feature `mpi`): `lzb` runs as Han & Zeiger's §IV parallel local
    /// z-buffer (the whole scene on every rank, the rays of the unfinished pixels shared; needs
    /// `lzb:payoff=off`) instead of sort-last. Every other renderer stays sort-last.
    #[arg(long, global = true)]
    pub mpi_lzb: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render one frame to PNG and print its statistics.
    Render(RenderArgs),
    /// Fly a camera path with one renderer: per-frame statistics, optional PNG per frame.
    Walk(WalkArgs),
    /// Run several renderers on the same scene(s) and path, and measure them against each other.
    Compare(CompareArgs),
    /// Describe a scene file or spec: triangles, nodes, instances, bounds, memory.
    Info(InfoArgs),
    /// List the built-in scene generators and their parameters.
    Scenes(ScenesArgs),
    /// List the renderers and their parameters (set as `name:key=value,key=value`).
    Algos(AlgosArgs),
    /// Vary one renderer parameter over a list of values: a comparison per value, with mean
    /// frame time and counters plotted against it.
    Sweep(SweepArgs),
    /// Particle culling with an N-buffer (Décoret §3.2): sprites among a scene, culled or not.
    Particles(crate::commands::particles::ParticlesArgs),
    /// Shadow volumes of a spot light, clamped with litmaps and N-buffers (Décoret §3.3) or not.
    Shadows(crate::commands::shadows::ShadowsArgs),
    /// The performance yardstick: a fixed, versioned matrix of scenes and camera paths, every
    /// renderer on each; per case and renderer the speedup over zbuffer, the ratio to the
    /// oracle and identical frames, then per renderer the geometric mean and worst case.
    Suite(SuiteArgs),
    /// Open a scene in a window: fly through it, switch renderers live, see what each costs
    /// and culls (press H in the window for the controls).
    #[cfg(feature = "view")]
    View(crate::view::ViewArgs),
    /// Open a scene in a window (this build has no viewer: build with `--features view`).
    #[cfg(not(feature = "view"))]
    View {
        /// Ignored: this build has no viewer.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        ignored: Vec<String>,
    },
    /// Sort-last compositing's communication per frame and rank: measured over 2–8 thread
    /// ranks on a scene, and binary swap's model for many ranks at a large frame size; a table,
    /// JSON, CSV and a plot.
    MpiModel(crate::commands::mpi_model::MpiModelArgs),
}

/// A frame size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Size {
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
}

/// `occult render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Scene: a generator spec (`city:blocks=8`, see `occult scenes`) or a file (.obj, .ply,
    /// .gltf, .glb).
    #[arg(long, value_name = "SPEC", value_parser = parse_scene)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Renderer with its settings, `name` or `name:key=value,...` (see `occult algos`).
    #[arg(long, value_name = "SPEC", default_value = "frustum", value_parser = parse_algorithm)]
    pub algo: AlgoSpec,
    /// Frame size, WxH pixels.
    #[arg(long, value_name = "WxH", default_value = "1920x1080", value_parser = parse_size)]
    pub size: Size,
    /// Color image out (PNG).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Depth visualisation out (PNG, grey: near white, far dark).
    #[arg(long, value_name = "FILE")]
    pub depth_out: Option<PathBuf>,
    /// Frame statistics out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// One camera: a view of the scene, with some of its fields overridden.
#[derive(Debug, Args, Clone)]
pub struct CameraArgs {
    /// Camera: `default` (the scene's), or camera `i` of a path, as `PATH:i` (`circle:8:3`,
    /// `default:0`, `cams.json:2`); a path without index gives its first camera. `circle:3` is
    /// the path of three views, as for `--path`: camera 3 of a bare `circle` is
    /// `circle:120:3`.
    #[arg(long, value_name = "VIEW", default_value = "default", value_parser = parse_view)]
    pub view: ViewArg,
    #[command(flatten)]
    pub overrides: CameraOverrides,
}

/// The frames of a command that flies a camera path: the path's cameras, at one frame size.
#[derive(Debug, Args, Clone)]
pub struct FramesArgs {
    /// Camera path: `circle:N`, `street:N`, `flyover:N`, `default`, or a JSON file of cameras.
    #[arg(long, value_name = "PATH", default_value = "circle:16", value_parser = parse_path)]
    pub path: PathArg,
    /// Frame size, WxH pixels.
    #[arg(long, value_name = "WxH", default_value = "640x480", value_parser = parse_size)]
    pub size: Size,
}

/// Camera fields that override the chosen view's.
#[derive(Debug, Args, Clone, Default)]
pub struct CameraOverrides {
    /// Eye position, world units, `x,y,z`.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<Vec3>,
    /// Point looked at, `x,y,z`.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<Vec3>,
    /// Up direction, `x,y,z`.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<Vec3>,
    /// Vertical field of view, degrees.
    #[arg(long, value_name = "DEG", value_parser = parse_finite, allow_negative_numbers = true)]
    pub fov: Option<f32>,
    /// Near plane distance.
    #[arg(long, value_name = "DIST", value_parser = parse_finite, allow_negative_numbers = true)]
    pub near: Option<f32>,
    /// Far plane distance.
    #[arg(long, value_name = "DIST", value_parser = parse_finite, allow_negative_numbers = true)]
    pub far: Option<f32>,
}

impl CameraOverrides {
    /// The checks of [`Camera::validate`] that need no scene, on the fields given: the field of
    /// view, the near and far planes, and eye, target and up when eye and target are both
    /// given. Run before the scene is built, so that a bad camera fails first; the camera as a
    /// whole is checked again once the scene's fills the fields not given.
    ///
    /// # Errors
    /// [`CoreError::DegenerateCamera`], as [`Camera::validate`] words it.
    pub fn check(&self) -> Result<(), CoreError> {
        let probe = Camera::look_at(Vec3::Z, Vec3::ZERO);
        if let Some(fov) = self.fov {
            Camera {
                fov_y_deg: fov,
                ..probe
            }
            .validate()?;
        }
        match (self.near, self.far) {
            (Some(near), Some(far)) => Camera { near, far, ..probe }.validate()?,
            (Some(near), None) => Camera {
                near,
                far: 2.0 * near.abs() + 1.0,
                ..probe
            }
            .validate()?,
            (None, Some(far)) if far <= 0.0 => {
                return Err(CoreError::DegenerateCamera(format!("far plane {far} is not positive")))
            }
            _ => {}
        }
        if let (Some(eye), Some(target)) = (self.eye, self.target) {
            Camera {
                eye,
                target,
                up: self.up.unwrap_or(Vec3::Y),
                ..probe
            }
            .validate()
            .or_else(|e| match (self.up, e) {
                // The scene's up may suit a view along +-y where the default +y does not.
                (None, CoreError::DegenerateCamera(why)) if why.starts_with("up is parallel") => Ok(()),
                (_, e) => Err(e),
            })?;
        }
        Ok(())
    }
}

/// `occult walk`.
#[derive(Debug, Args)]
pub struct WalkArgs {
    /// Scene spec or file (see `occult render --help`).
    #[arg(long, value_name = "SPEC", value_parser = parse_scene)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub frames: FramesArgs,
    /// Renderer with its settings, `name` or `name:key=value,...` (see `occult algos`).
    #[arg(long, value_name = "SPEC", default_value = "frustum", value_parser = parse_algorithm)]
    pub algo: AlgoSpec,
    /// Write each frame as DIR/frame_00000.png (created if missing).
    #[arg(long, value_name = "DIR")]
    pub frames_out: Option<PathBuf>,
    /// Per-frame statistics out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Per-frame statistics out (CSV, one row per frame).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// The path's cameras out, as a JSON file of views that `--path` reads back (every field
    /// written): a generated walk saved to be edited or replayed.
    #[arg(long, value_name = "FILE")]
    pub path_out: Option<PathBuf>,
}

/// `occult compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Scene spec or file; repeat for several scenes (for example growing sizes, with
    /// `--plot-scaling`).
    #[arg(long, value_name = "SPEC", required = true, value_parser = parse_scene)]
    pub scene: Vec<SceneArg>,
    #[command(flatten)]
    pub frames: FramesArgs,
    /// Renderers, comma-separated, each with its settings, or `all` (every renderer with default
    /// settings). Settings follow their renderer: `zbuffer,hzb:leaf=64,temporal=off,hzb` is three
    /// renderers, reported by these labels. The reference (see --reference) is always rendered
    /// and reported.
    #[arg(long, value_name = "A,B,..", default_value = "all", value_parser = parse_algorithms)]
    pub algos: AlgorithmList,
    /// Full report out (JSON: per renderer summary and per-frame records).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Per-frame records out (CSV: one row per scene, renderer and frame; the oracle as
    /// renderer `oracle`).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Plot of frame time per frame, per renderer (PNG; one panel per scene).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// What `--plot` shows per frame: `time`, `submitted` or `rasterized` triangles (with the
    /// exactly visible ones dashed), or the name of a renderer counter (`queries`,
    /// `cells_visible`, ...; see the text report).
    #[arg(long, value_name = "WHAT", default_value = "time")]
    pub plot_y: String,
    /// Plot of mean frame time against scene size (PNG; needs two or more --scene).
    #[arg(long, value_name = "FILE")]
    pub plot_scaling: Option<PathBuf>,
    /// The scaling plot's x axis: `triangles` (scene size), `covered` (covered pixels),
    /// `image` (image complexity: screen area of every triangle in view, hidden or not) or
    /// `depth` (depth complexity: image complexity over covered pixels). `image` and `depth`
    /// measure the image complexity (one untimed pass over the scene per view). Several,
    /// comma-separated, draw one plot each from the same run: `F.png` becomes `F-<axis>.png`.
    #[arg(long, value_name = "AXIS[,AXIS...]", default_value = "triangles", value_delimiter = ',', value_parser = ["triangles", "covered", "image", "depth"])]
    pub plot_scaling_x: Vec<String>,
    /// Measure each view's image and depth complexity (one untimed pass over every triangle in
    /// view per view); reported in the text, JSON and CSV.
    #[arg(long)]
    pub complexity: bool,
    /// Measure peak resident memory (Linux): per renderer, the peak RSS of the whole process
    /// while it was built and rendered, and the process's own peak. It resets this process's
    /// kernel high-water mark before every build and frame; each reading is of the whole
    /// process (the scene and the other renderers' structures included). Off: the peak RSS
    /// column, fields and CSV column are empty.
    #[arg(long)]
    pub peak_rss: bool,
    /// For every frame that differs from the reference, an image of where, into DIR (created if
    /// missing) as `LABEL-frame_00000.png` (`sceneN-LABEL-...` with several scenes; characters
    /// other than letters, digits, `.`, `_` and `-` in a label become `_`): pixels wrong by the
    /// paper's criterion (an item not visible through the pixel) red, another item visible
    /// through the pixel yellow, the rest the reference's color dimmed.
    #[arg(long, value_name = "DIR")]
    pub diff_out: Option<PathBuf>,
    /// What frames are checked against: `auto` (zbuffer, or frustum on scenes too large for
    /// brute force), `none` (nothing checked, no oracle: for scenes too large even for frustum)
    /// or a conservative renderer's spec.
    #[arg(long, value_name = "auto|none|SPEC", default_value = "auto", value_parser = parse_reference)]
    pub reference: ReferenceArg,
}

/// A parsed `--reference`.
#[derive(Clone, Debug)]
pub struct ReferenceArg(pub occult_harness::compare::Reference);

/// `auto`, `none` or an algorithm spec.
pub fn parse_reference(s: &str) -> Result<ReferenceArg, String> {
    use occult_harness::compare::Reference;
    Ok(ReferenceArg(match s.trim() {
        "auto" => Reference::Auto,
        "none" => Reference::None,
        spec => Reference::Spec(parse_algorithm(spec)?),
    }))
}

/// A parsed `--algos` list (a newtype, because clap treats `Vec` as "many values").
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AlgorithmList(pub Vec<AlgoSpec>);

/// `occult info`.
#[derive(Debug, Args)]
pub struct InfoArgs {
    /// Scene file or generator spec.
    #[arg(value_name = "FILE|SPEC", value_parser = parse_scene)]
    pub scene: SceneArg,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `occult scenes`.
#[derive(Debug, Args)]
pub struct ScenesArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `occult sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// Scene spec or file.
    #[arg(long, value_name = "SPEC", value_parser = parse_scene)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub frames: FramesArgs,
    /// Renderers compared at every value (as `occult compare --algos`); the varied one must be
    /// among them.
    #[arg(long, value_name = "A,B,..", value_parser = parse_algorithms)]
    pub algos: AlgorithmList,
    /// The parameter and its values: `ALGO.KEY=V1,V2,...` (numbers), set on every spec of ALGO
    /// in --algos.
    #[arg(long, value_name = "ALGO.KEY=V1,V2,..", value_parser = crate::commands::sweep::parse_vary)]
    pub vary: occult_harness::sweep::Vary,
    /// A renderer counter (see `occult compare` output) to tabulate and plot against the value;
    /// repeat for several.
    #[arg(long, value_name = "NAME")]
    pub counter: Vec<String>,
    /// Logarithmic x axis in the plot.
    #[arg(long)]
    pub log_x: bool,
    /// Every comparison out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// The table out (CSV).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Mean frame time (and each --counter) against the value (PNG).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// What frames are checked against, as `occult compare --reference`.
    #[arg(long, value_name = "auto|none|SPEC", default_value = "auto", value_parser = parse_reference)]
    pub reference: ReferenceArg,
}

/// `occult suite`.
#[derive(Debug, Args)]
pub struct SuiteArgs {
    /// The quick subset (small scenes, few frames, a smaller default size): for CI.
    #[arg(long)]
    pub quick: bool,
    /// Only these cases, comma-separated, by name (see --list).
    #[arg(long, value_name = "A,B,..", value_delimiter = ',')]
    pub cases: Option<Vec<String>>,
    /// Renderers, as `occult compare --algos`; zbuffer is always measured.
    #[arg(long, value_name = "A,B,..", default_value = "all", value_parser = parse_algorithms)]
    pub algos: AlgorithmList,
    /// Frame size, WxH pixels; default 1280x720, 640x360 with --quick.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<Size>,
    /// Frames of every case, instead of the suite's own counts.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=i64::from(occult_scenes::path::MAX_VIEWS)))]
    pub frames: Option<u32>,
    /// Runs of every case, 1-100: each builds every renderer afresh and renders every frame.
    /// The speedups pool the runs; a slowdown is beyond noise only when every run's speedup
    /// and the frames' 90% interval lie below 1.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeat: u32,
    /// The folder of the real models; default: $OCCULT_MODELS, else ../shared/models when it
    /// exists. Model cases whose file is missing are skipped.
    #[arg(long, value_name = "DIR")]
    pub models: Option<PathBuf>,
    /// Full report out (JSON: per case every renderer's comparison, the summary, the
    /// violations).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Chart out (PNG): per case, each renderer's speedup over zbuffer and its ratio to the
    /// oracle.
    #[arg(long, value_name = "FILE")]
    pub chart: Option<PathBuf>,
    /// Print the cases (with the suite's version) and exit.
    #[arg(long)]
    pub list: bool,
}

/// `occult algos`.
#[derive(Debug, Args)]
pub struct AlgosArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// A spec named on the command line: the text as given (which is how it is shown) and what it
/// parses to.
#[derive(Clone, Debug)]
pub struct Given<T> {
    /// As given.
    pub text: String,
    /// Parsed and checked as far as it can be before any work.
    pub spec: T,
}

impl<T> std::fmt::Display for Given<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

/// A scene: generator parameters checked, a file known to exist.
pub type SceneArg = Given<SceneSpec>;

/// A scene spec, checked as far as it can be without building the scene: a generator's
/// parameters in full, a file's existence (its contents are read when the scene is built).
pub fn parse_scene(s: &str) -> Result<SceneArg, String> {
    let spec = occult_scenes::parse_spec(s).map_err(|e| e.to_string())?;
    if let SceneSpec::File(path) = &spec {
        match std::fs::metadata(path) {
            Ok(m) if m.is_file() => {}
            Ok(_) => return Err(format!("{} is not a file", path.display())),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        }
    }
    Ok(SceneArg {
        text: s.to_string(),
        spec,
    })
}

/// A camera path: kind and count checked, a file read.
pub type PathArg = Given<PathSpec>;

/// A camera path spec ([`PathSpec::parse`]).
pub fn parse_path(s: &str) -> Result<PathArg, String> {
    Ok(PathArg {
        text: s.to_string(),
        spec: PathSpec::parse(s).map_err(|e| e.to_string())?,
    })
}

/// One camera named on the command line: the text as given and the spec it parses to.
#[derive(Clone, Debug)]
pub struct ViewArg {
    /// As given.
    pub text: String,
    /// Parsed: the path checked, the index within it.
    pub spec: ViewSpec,
}

/// A view spec ([`ViewSpec::parse`]): `PATH` or `PATH:i`.
pub fn parse_view(s: &str) -> Result<ViewArg, String> {
    Ok(ViewArg {
        text: s.to_string(),
        spec: ViewSpec::parse(s).map_err(|e| e.to_string())?,
    })
}

/// `WxH`, checked against the engine's resolution limits.
pub fn parse_size(s: &str) -> Result<Size, String> {
    let bad = || format!("expected WxH in pixels, like 1920x1080, not '{s}'");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let width: u32 = w.trim().parse().map_err(|_| bad())?;
    let height: u32 = h.trim().parse().map_err(|_| bad())?;
    occult_core::check_resolution(width, height).map_err(|e| e.to_string())?;
    Ok(Size { width, height })
}

/// `x,y,z`, finite.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let bad = || format!("expected three comma-separated numbers x,y,z, not '{s}'");
    if parts.len() != 3 {
        return Err(bad());
    }
    let mut v = [0.0f32; 3];
    for (slot, p) in v.iter_mut().zip(&parts) {
        *slot = p.parse().map_err(|_| bad())?;
        if !slot.is_finite() {
            return Err(format!("'{p}' is not a finite number"));
        }
    }
    Ok(Vec3::from_array(v))
}

/// A finite number.
pub fn parse_finite(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("expected a finite number, not '{s}'")),
    }
}

/// A thread count in 1..=1024.
pub fn parse_threads(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n @ 1..=1024) => Ok(n),
        _ => Err(format!("expected a thread count from 1 to 1024, not '{s}'")),
    }
}

/// One algorithm spec, `name` or `name:key=value,...`, keys and values checked
/// ([`AlgoSpec::validate`]).
pub fn parse_algorithm(s: &str) -> Result<AlgoSpec, String> {
    let spec = AlgoSpec::parse(s).map_err(|e| e.to_string())?;
    spec.validate().map_err(|e| e.to_string())?;
    Ok(spec)
}

/// Comma-separated algorithm specs (duplicates dropped; keys and values checked), or `all`.
pub fn parse_algorithms(s: &str) -> Result<AlgorithmList, String> {
    if s.trim() == "all" {
        return Ok(AlgorithmList(
            Algorithm::all().into_iter().map(AlgoSpec::from).collect(),
        ));
    }
    let mut list: Vec<AlgoSpec> = Vec::new();
    for spec in AlgoSpec::parse_list(s).map_err(|e| e.to_string())? {
        spec.validate().map_err(|e| e.to_string())?;
        if !list.iter().any(|a| a.label() == spec.label()) {
            list.push(spec);
        }
    }
    Ok(AlgorithmList(list))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(
            parse_size("640x480"),
            Ok(Size {
                width: 640,
                height: 480
            })
        );
        assert_eq!(parse_size("64X48"), Ok(Size { width: 64, height: 48 }));
        for bad in ["0x0", "99999x99999", "abc", "640", "640x", "x480", "-1x5", "1.5x2", ""] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn vectors_and_numbers() {
        assert_eq!(parse_vec3("1,-2, 3.5"), Ok(Vec3::new(1.0, -2.0, 3.5)));
        for bad in ["1,2", "1,2,3,4", "a,b,c", "nan,0,0", "inf,0,0", ""] {
            assert!(parse_vec3(bad).is_err(), "{bad}");
        }
        assert!(parse_finite("NaN").is_err());
        assert!(parse_threads("0").is_err());
        assert_eq!(parse_threads("2"), Ok(2));
    }

    #[test]
    fn algorithm_lists() {
        let all: Vec<Algorithm> = parse_algorithms("all")
            .expect("all is a valid algorithm list")
            .0
            .iter()
            .map(|s| s.algorithm)
            .collect();
        assert_eq!(all, Algorithm::all());
        let labels = |s: &str| -> Vec<String> {
            parse_algorithms(s)
                .expect("every listed algorithm list is valid")
                .0
                .iter()
                .map(|a| a.label())
                .collect()
        };
        assert_eq!(labels("frustum, zbuffer,frustum"), ["frustum", "zbuffer"]);
        assert_eq!(
            labels("frustum:leaf=8,group_leaf=2,frustum,frustum:leaf=8,group_leaf=2"),
            ["frustum:leaf=8,group_leaf=2", "frustum"]
        );
        let e = parse_algorithms("frustum:leaves=8").unwrap_err();
        assert!(e.contains("leaves") && e.contains("group_leaf"), "{e}");
        let e = parse_algorithms("zbuffer,warp").unwrap_err();
        assert!(e.contains("warp") && e.contains("frustum"), "{e}");
        assert!(parse_algorithms("zbuffer,,frustum").is_err());
    }

    #[test]
    fn setting_values_are_checked_when_parsed() {
        let e = parse_algorithms("zbuffer,frustum:leaf=abc").unwrap_err();
        assert!(e.contains("leaf=abc"), "{e}");
        assert!(parse_algorithm("frustum:leaf=0").is_err());
        assert!(parse_reference("hzb:temporal=maybe").is_err());
        assert!(parse_algorithm("frustum:leaf=8").is_ok());
    }

    #[test]
    fn negative_numbers_reach_our_checks() {
        use clap::Parser;
        let parse = |args: &[&str]| {
            let mut all = vec!["occult", "render", "--scene", "terrain:g=2", "--out", "x.png"];
            all.extend_from_slice(args);
            Cli::try_parse_from(all)
        };
        for (flag, value) in [("--fov", "-10"), ("--near", "-1"), ("--far", "-5")] {
            let cli = parse(&[flag, value]).unwrap_or_else(|e| panic!("{flag} {value}: {e}"));
            let Command::Render(r) = cli.command else {
                unreachable!()
            };
            let e = r.camera.overrides.check().unwrap_err().to_string();
            assert!(e.contains(value), "{flag}: {e}");
        }
        let cli =
            parse(&["--eye", "-1,2,3", "--target", "-1,2,3"]).expect("negative coordinates parse as values, not flags");
        let Command::Render(r) = cli.command else {
            unreachable!()
        };
        assert!(r.camera.overrides.check().unwrap_err().to_string().contains("coincide"));
        let cli = parse(&["--fov", "45", "--near", "0.5", "--eye", "0,5,0", "--target", "0,0,0"])
            .expect("a valid camera parses");
        let Command::Render(r) = cli.command else {
            unreachable!()
        };
        r.camera
            .overrides
            .check()
            .expect("fov 45, near 0.5 and distinct eye and target are valid");
    }

    #[test]
    fn scenes_paths_and_views_are_checked_when_parsed() {
        assert!(parse_scene("city:blocks=A").unwrap_err().contains("blocks"));
        assert!(parse_scene("no/such/model.obj").unwrap_err().contains("model.obj"));
        assert!(parse_path("circle:0").is_err());
        assert!(parse_view("circle:0").is_err(), "as --path circle:0");
        assert_eq!(
            parse_view("circle:8:3")
                .expect("an index below the count is a valid view")
                .spec
                .index,
            3
        );
        assert!(parse_view("circle:8:8").unwrap_err().contains("index 8"));
    }

    #[test]
    fn cli_definition_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }
}
