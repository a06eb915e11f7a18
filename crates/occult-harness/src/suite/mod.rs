//! The performance yardstick: a fixed, versioned matrix of cases, every renderer on each, one
//! process.
//!
//! A **case** ([`Case`]) is a scene (a generator spec or a model file of the models folder), a
//! camera path kind and a frame count. The suite's definition, the list [`CASES`] with its
//! [`SUITE_VERSION`], lives in one file, `suite/cases.rs`, so that figures compare across
//! commits: two reports compare when their `suite_version`, frame size and renderers agree.
//!
//! [`run_suite`] builds each case's scene and path and runs a [`compare`] on it (every
//! renderer interleaved frame by frame against the reference and the oracle; see that module
//! for what is measured and how), then summarises:
//!
//! - per case and renderer ([`CaseRenderer`]): mean frame time, **speedup over `zbuffer`**
//!   (zbuffer's mean time over the renderer's, > 1 is faster), **ratio to the oracle** (the
//!   renderer's mean time over the time to rasterize exactly the visible triangles; 1 is
//!   perfect culling at no cost), frames identical to the reference's, frames drawn directly
//!   because culling did not pay there (counter `payoff_direct`), triangles rasterized beside
//!   those visible;
//! - per renderer over the cases ([`RendererSummary`]): the geometric mean and the worst case of
//!   both ratios (worst: the lowest speedup, the highest oracle ratio), with the case it
//!   occurred on;
//! - the **violations** of what the project demands of conservative renderers on every case
//!   ([`Violation`]): at least as fast as `zbuffer` (speedup ≥ 1) and frames identical to the
//!   reference. Each broken demand of a renderer on a case is one violation; the report counts
//!   them ([`SuiteReport::violation_count`]), and those beyond the noise apart
//!   ([`SuiteReport::significant_violation_count`]: frames that differ, or a speedup whose
//!   90 % bootstrap interval over the case's frames, [`speedup_interval`], lies wholly below
//!   1). Approximate renderers (`rzb`) are measured but owe neither.
//!
//! Cases whose model file is missing are skipped and listed with the path
//! ([`SuiteReport::skipped`]); so are all model cases when no models folder is given. A models
//! folder that is given but cannot be read is an error.
//!
//! Reading a report: speedups and oracle ratios are ratios of times measured in the same
//! process, interleaved, so they hold across machines far better than the times themselves;
//! a geometric mean is the typical factor over the cases, the worst case says where a renderer
//! loses. Times are wall-clock times of whole frames, noisy on a shared machine: a speedup
//! near 1 can fall either side of it from one run to the next, which its interval shows.
//!
//! Cost: the sum of the cases' comparisons; one scene is held at a time.
//!
//! ```
//! use occult_harness::suite::{run_suite, Case, CaseScene, SuiteConfig};
//! use occult_render::Algorithm;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let cases = [Case {
//!     name: "tiny-orbit",
//!     scene: CaseScene::Generated("terrain:g=8"),
//!     path: "circle",
//!     frames: 2,
//!     quick: true,
//! }];
//! let config = SuiteConfig::new([Algorithm::ZBUFFER, Algorithm::FRUSTUM], 32, 24);
//! let report = run_suite(&cases, &config, &mut |_| {})?;
//! let frustum = report.summary.iter().find(|r| r.name == "frustum").expect("frustum is in the summary");
//! assert_eq!(frustum.frames_identical, Some(2));
//! assert!(frustum.speedup_geomean.is_some());
//! # Ok(())
//! # }
//! ```

mod cases;
mod report;
#[cfg(test)]
mod tests;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use occult_render::{AlgoSpec, RenderOptions};
use occult_scenes::{PathError, PathSpec, SceneSpec, SpecError};
use thiserror::Error;

use crate::compare::{compare, CompareConfig, CompareError, CompareProgress, Reference};
pub use cases::{
    default_size, select, Case, CaseScene, CASES, DEFAULT_SIZE, QUICK_MAX_FRAMES, QUICK_SIZE, SUITE_VERSION,
};
pub use report::{
    speedup_interval, CaseRenderer, CaseReport, RendererSummary, SkippedCase, SuiteReport, Violation, ViolationKind,
    Worst, INTERVAL,
};

/// Errors of [`run_suite`] and [`select`].
#[derive(Debug, Error)]
pub enum SuiteError {
    /// A case name that is not in [`CASES`].
    #[error("unknown case '{name}'; the cases are: {valid}")]
    UnknownCase {
        /// The name given.
        name: String,
        /// The valid names, comma-separated.
        valid: String,
    },
    /// No case to run.
    #[error("no case to run")]
    NoCases,
    /// Zero runs of each case asked for.
    #[error("repeats must be at least 1")]
    NoRuns,
    /// The models folder was given but cannot be read.
    #[error("models folder '{}'", path.display())]
    Models {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A case's scene could not be built.
    #[error("case {case}: scene '{scene}'")]
    Scene {
        /// The case.
        case: String,
        /// Its scene.
        scene: String,
        /// Why.
        source: SpecError,
    },
    /// A case's camera path could not be made.
    #[error("case {case}: path '{path}'")]
    Path {
        /// The case.
        case: String,
        /// Its path spec.
        path: String,
        /// Why.
        source: PathError,
    },
    /// A case's comparison failed.
    #[error("case {case}")]
    Compare {
        /// The case.
        case: String,
        /// Why.
        source: CompareError,
    },
}

/// What to run every case with.
#[derive(Clone, Debug)]
pub struct SuiteConfig {
    /// Renderers, as [`CompareConfig::algorithms`]; `zbuffer` is added as the reference where
    /// it is missing, so speedups are always measured.
    pub algorithms: Vec<AlgoSpec>,
    /// Options every renderer is built with.
    pub options: RenderOptions,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// The folder model files are relative to; `None`: model cases are skipped.
    pub models: Option<PathBuf>,
    /// Runs of every case, at least 1: each builds every renderer afresh and renders every
    /// frame (its first included), so that the speedups pool the runs and their intervals
    /// hold the drift from one run to the next, not only the noise between frames.
    pub repeats: usize,
}

impl SuiteConfig {
    /// `algorithms` at `width × height`, default options, no models folder.
    pub fn new<A: Into<AlgoSpec>>(algorithms: impl IntoIterator<Item = A>, width: u32, height: u32) -> Self {
        Self {
            algorithms: algorithms.into_iter().map(Into::into).collect(),
            options: RenderOptions::default(),
            width,
            height,
            models: None,
            repeats: 1,
        }
    }
}

/// Progress events, for progress bars and for printing each case as it ends.
#[derive(Clone, Copy, Debug)]
pub enum SuiteProgress<'a> {
    /// About to build the scene of case `index` of `count`.
    Case {
        /// The case.
        case: &'a Case,
        /// Its position, from 0.
        index: usize,
        /// Cases in all.
        count: usize,
    },
    /// The comparison of the current case moved on.
    Compare {
        /// The case.
        case: &'a Case,
        /// Which run of the case, from 0 ([`SuiteConfig::repeats`]).
        run: usize,
        /// What happened.
        event: CompareProgress<'a>,
    },
    /// The case is skipped (its model file is missing).
    Skipped(&'a SkippedCase),
    /// The case is done.
    Done(&'a CaseReport),
}

/// Runs `cases` (normally a [`select`]ion of [`CASES`]) with `config`, in order (module doc).
///
/// # Errors
/// [`SuiteError::NoCases`] for an empty slice; [`SuiteError::Models`] when the models folder
/// cannot be read; [`SuiteError::Scene`], [`SuiteError::Path`] and [`SuiteError::Compare`]
/// when a case fails (a missing model file is not an error: the case is skipped).
pub fn run_suite(
    cases: &[Case],
    config: &SuiteConfig,
    progress: &mut dyn FnMut(SuiteProgress),
) -> Result<SuiteReport, SuiteError> {
    if cases.is_empty() {
        return Err(SuiteError::NoCases);
    }
    if config.repeats == 0 {
        return Err(SuiteError::NoRuns);
    }
    if let Some(models) = &config.models {
        std::fs::read_dir(models).map_err(|source| SuiteError::Models {
            path: models.clone(),
            source,
        })?;
    }
    let compare_config = CompareConfig {
        algorithms: config.algorithms.clone(),
        options: config.options.clone(),
        width: config.width,
        height: config.height,
        reference: Reference::Auto,
        image_complexity: false,
        peak_rss: None,
        diff_images: false,
    };
    let mut done = Vec::with_capacity(cases.len());
    let mut skipped = Vec::new();
    for (index, case) in cases.iter().enumerate() {
        progress(SuiteProgress::Case {
            case,
            index,
            count: cases.len(),
        });
        match run_case(case, config, &compare_config, progress)? {
            Ok(report) => {
                progress(SuiteProgress::Done(&report));
                done.push(report);
            }
            Err(skip) => {
                progress(SuiteProgress::Skipped(&skip));
                skipped.push(skip);
            }
        }
    }
    Ok(SuiteReport::new(config, done, skipped))
}

/// One case: its report, or why it is skipped.
fn run_case(
    case: &Case,
    config: &SuiteConfig,
    compare_config: &CompareConfig,
    progress: &mut dyn FnMut(SuiteProgress),
) -> Result<Result<CaseReport, SkippedCase>, SuiteError> {
    let start = Instant::now();
    let spec = match case.scene {
        CaseScene::Generated(spec) => occult_scenes::parse_spec(spec).map_err(|source| scene_error(case, source))?,
        CaseScene::Model(file) => {
            let Some(models) = &config.models else {
                return Ok(Err(SkippedCase::new(case, None, "no models folder given")));
            };
            let path = models.join(file);
            if !path.is_file() {
                return Ok(Err(SkippedCase::new(case, Some(&path), "model file missing")));
            }
            SceneSpec::File(path)
        }
    };
    let built = spec.build().map_err(|source| scene_error(case, source))?;
    let scene_build_ms = start.elapsed().as_secs_f64() * 1e3;
    let path = case.path_spec();
    let cameras = PathSpec::parse(&path)
        .and_then(|p| p.views(&built.scene, &built.default_camera))
        .map_err(|source| SuiteError::Path {
            case: case.name.to_string(),
            path: path.clone(),
            source,
        })?;
    let scene = Arc::new(built.scene);
    let mut runs = Vec::new();
    for run in 0..config.repeats {
        let report = compare(Arc::clone(&scene), &cameras, compare_config, &mut |event| {
            progress(SuiteProgress::Compare { case, run, event })
        })
        .map_err(|source| SuiteError::Compare {
            case: case.name.to_string(),
            source,
        })?;
        runs.push(report);
    }
    let mut runs = runs.into_iter();
    // `repeats` is at least 1 (checked by `run_suite`).
    let first = runs.next().ok_or(SuiteError::NoRuns)?;
    let more = runs.collect();
    Ok(Ok(CaseReport::new(
        case,
        built.name,
        scene_build_ms,
        start.elapsed().as_secs_f64(),
        first,
        more,
    )))
}

fn scene_error(case: &Case, source: SpecError) -> SuiteError {
    SuiteError::Scene {
        case: case.name.to_string(),
        scene: case.scene.to_string(),
        source,
    }
}
