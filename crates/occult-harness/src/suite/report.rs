//! What [`run_suite`](super::run_suite) returns: per case the comparison and its compact
//! summary, per renderer the summary over the cases, and the violations.

use std::path::Path;

use serde::Serialize;

use super::{Case, CaseScene, SuiteConfig, SUITE_VERSION};
use crate::compare::{CompareReport, RendererReport};

/// One renderer on one case: the figures the suite is read by.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CaseRenderer {
    /// The renderer's label.
    pub name: String,
    /// Its frames must be identical to the reference's.
    pub conservative: bool,
    /// The case's reference renderer.
    pub is_reference: bool,
    /// Mean frame time, ms.
    pub mean_ms: f64,
    /// `zbuffer`'s mean time over this renderer's (> 1: faster), over every run of the case;
    /// `None` without `zbuffer`.
    pub speedup_vs_zbuffer: Option<f64>,
    /// The speedup of each run of the case, in order (one run unless the suite repeats its
    /// cases: [`SuiteConfig::repeats`]); empty without `zbuffer`, and without a run whose
    /// renderer took no time (no ratio).
    pub speedup_runs: Vec<f64>,
    /// The [`INTERVAL`] bootstrap interval of the speedup over the frames of every run (see
    /// [`speedup_interval`]), widened to hold each run's own speedup: how far the machine's
    /// noise moves it, within a run and from one run to the next; `None` without `zbuffer`.
    pub speedup_interval: Option<[f64; 2]>,
    /// This renderer's mean time over the oracle's (1: perfect culling at no cost); `None`
    /// without an oracle.
    pub vs_oracle: Option<f64>,
    /// Frames identical to the reference's, over every run; `None` when nothing was checked.
    pub frames_identical: Option<usize>,
    /// Frames rendered, over every run.
    pub frames: usize,
    /// Frames it drew directly, as `frustum` does, because its culling did not pay there
    /// (counter `payoff_direct`; DESIGN invariant 5), over every run.
    pub direct_frames: usize,
    /// Mean triangles rasterized per frame.
    pub triangles_rasterized: f64,
    /// Mean exactly visible triangles per frame (the same for every renderer of the case).
    pub triangles_visible: f64,
}

impl CaseRenderer {
    /// The figures of one renderer over the runs of a case: `runs` its report of each run, in
    /// order (at least one), `zbuffer` `zbuffer`'s of the same runs when it ran, `oracle_ms`
    /// the oracle's mean time of each run when there was one. One run gives that run's
    /// figures unchanged; several pool their frames (every run's first frame included).
    fn of(runs: &[&RendererReport], zbuffer: Option<&[&RendererReport]>, oracle_ms: Option<&[f64]>) -> Self {
        let first = runs[0];
        let count = runs.len() as f64;
        let summed_ms: f64 = runs.iter().map(|r| r.mean_ms).sum();
        let mean_ms = summed_ms / count;
        let times = |rs: &[&RendererReport]| {
            rs.iter()
                .flat_map(|r| r.per_frame.iter().map(|f| f.time_ms))
                .collect::<Vec<_>>()
        };
        let speedup_runs: Vec<f64> = zbuffer.map_or_else(Vec::new, |z| {
            z.iter()
                .zip(runs)
                .filter_map(|(z, r)| r.speedup_vs_zbuffer.or_else(|| ratio(z.mean_ms, r.mean_ms)))
                .collect()
        });
        let (speedup_vs_zbuffer, vs_oracle) = if runs.len() == 1 {
            (first.speedup_vs_zbuffer, first.vs_oracle)
        } else {
            // Every run renders the same frames: a ratio of summed means is one of summed times
            // (summed alike, so that `zbuffer`'s own is exactly 1).
            (
                zbuffer.and_then(|z| ratio(z.iter().map(|r| r.mean_ms).sum(), summed_ms)),
                oracle_ms.and_then(|o| ratio(summed_ms, o.iter().sum())),
            )
        };
        let speedup_interval = zbuffer
            .and_then(|z| speedup_interval(&times(z), &times(runs)))
            .map(|i| if runs.len() > 1 { widened(i, &speedup_runs) } else { i });
        let checked: Vec<usize> = runs.iter().filter_map(|r| r.frames_identical).collect();
        Self {
            name: first.name.clone(),
            conservative: first.conservative,
            is_reference: first.is_reference,
            mean_ms,
            speedup_vs_zbuffer,
            speedup_runs,
            speedup_interval,
            vs_oracle,
            frames_identical: (checked.len() == runs.len()).then(|| checked.iter().sum()),
            frames: runs.iter().map(|r| r.frames).sum(),
            direct_frames: runs
                .iter()
                .flat_map(|r| &r.per_frame)
                .filter(|f| f.counters.get(occult_render::direct::COUNTER) > 0)
                .count(),
            triangles_rasterized: runs.iter().map(|r| r.triangles_rasterized).sum::<f64>() / count,
            triangles_visible: runs.iter().map(|r| r.triangles_visible).sum::<f64>() / count,
        }
    }

    /// Whether its speedup's interval lies wholly below 1: slower than `zbuffer` beyond what
    /// the noise explains.
    pub fn significantly_slower(&self) -> bool {
        self.speedup_interval.is_some_and(|[_, hi]| hi < 1.0)
    }

    /// What this renderer breaks of the demands on conservative renderers (none for an
    /// approximate one): slower than `zbuffer`, frames not identical.
    pub fn violations(&self) -> Vec<ViolationKind> {
        let mut broken = Vec::new();
        if !self.conservative {
            return broken;
        }
        if self.speedup_vs_zbuffer.is_some_and(|s| s < 1.0) {
            broken.push(ViolationKind::SlowerThanZbuffer);
        }
        if self.frames_identical.is_some_and(|n| n < self.frames) {
            broken.push(ViolationKind::FramesDiffer);
        }
        broken
    }
}

/// One case's results.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CaseReport {
    /// The case's name.
    pub name: String,
    /// Its scene (generator spec, or model file relative to the models folder).
    pub scene: CaseScene,
    /// The path spec run (`street:32`).
    pub path: String,
    /// Frames per renderer in one run (the renderers' own `frames` count every run).
    pub frames: usize,
    /// The scene's name.
    pub scene_name: String,
    /// Triangle instances in the scene.
    pub triangles: u64,
    /// Time to generate or load the scene, ms.
    pub scene_build_ms: f64,
    /// Wall time of the whole case (scene, renderer builds, frames, checks), seconds.
    pub seconds: f64,
    /// The reference renderer; `None` when nothing was checked.
    pub reference: Option<String>,
    /// The oracle's mean time, ms, over every run; `None` without a reference.
    pub oracle_ms: Option<f64>,
    /// Every renderer, in the comparison's order (the reference first when not requested).
    pub renderers: Vec<CaseRenderer>,
    /// The violations on this case.
    pub violations: Vec<Violation>,
    /// Runs of the case ([`SuiteConfig::repeats`]): each builds every renderer afresh and
    /// renders every frame.
    pub runs: usize,
    /// The first run's full comparison (per-frame records, counters, phases).
    pub compare: CompareReport,
    /// The other runs' comparisons, in order (none unless the suite repeats its cases).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub more_runs: Vec<CompareReport>,
}

impl CaseReport {
    /// The report of `case` from its comparison.
    pub(super) fn new(
        case: &Case,
        scene_name: String,
        scene_build_ms: f64,
        seconds: f64,
        compare: CompareReport,
        more_runs: Vec<CompareReport>,
    ) -> Self {
        let all: Vec<&CompareReport> = std::iter::once(&compare).chain(&more_runs).collect();
        // A renderer's report in every run, by name (every run compares the same renderers).
        let of_runs = |name: &str| -> Option<Vec<&RendererReport>> { all.iter().map(|c| c.renderer(name)).collect() };
        let zbuffer = of_runs("zbuffer");
        let oracle: Option<Vec<f64>> = all.iter().map(|c| c.oracle.as_ref().map(|o| o.mean_ms)).collect();
        let renderers: Vec<CaseRenderer> = compare
            .renderers
            .iter()
            .filter_map(|r| of_runs(&r.name))
            .map(|runs| CaseRenderer::of(&runs, zbuffer.as_deref(), oracle.as_deref()))
            .collect();
        let violations = renderers
            .iter()
            .flat_map(|r| {
                r.violations().into_iter().map(|kind| Violation {
                    case: case.name.to_string(),
                    renderer: r.name.clone(),
                    kind,
                    significant: kind == ViolationKind::SlowerThanZbuffer && r.significantly_slower(),
                    speedup_vs_zbuffer: r.speedup_vs_zbuffer,
                    speedup_interval: r.speedup_interval,
                    frames_identical: r.frames_identical,
                    frames: r.frames,
                })
            })
            .collect();
        Self {
            name: case.name.to_string(),
            scene: case.scene,
            path: case.path_spec(),
            frames: compare.frames,
            scene_name,
            triangles: compare.scene_triangles,
            scene_build_ms,
            seconds,
            reference: compare.reference.clone(),
            oracle_ms: oracle.as_ref().map(|o| o.iter().sum::<f64>() / o.len() as f64),
            renderers,
            violations,
            runs: all.len(),
            compare,
            more_runs,
        }
    }

    /// The renderer called `name`.
    pub fn renderer(&self, name: &str) -> Option<&CaseRenderer> {
        self.renderers.iter().find(|r| r.name == name)
    }
}

/// A demand on conservative renderers that one broke on one case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ViolationKind {
    /// Slower than `zbuffer` (speedup below 1).
    SlowerThanZbuffer,
    /// Some frames not identical to the reference's.
    FramesDiffer,
}

impl std::fmt::Display for ViolationKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::SlowerThanZbuffer => "slower than zbuffer",
            Self::FramesDiffer => "frames differ",
        })
    }
}

/// One violation: a conservative renderer, a case, the demand broken and the figures.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Violation {
    /// The case.
    pub case: String,
    /// The renderer.
    pub renderer: String,
    /// What it broke.
    pub kind: ViolationKind,
    /// For [`ViolationKind::SlowerThanZbuffer`]: the speedup's interval lies wholly below 1
    /// ([`CaseRenderer::significantly_slower`]), so noise does not explain it.
    pub significant: bool,
    /// Its speedup over `zbuffer` on the case.
    pub speedup_vs_zbuffer: Option<f64>,
    /// Its speedup's interval ([`CaseRenderer::speedup_interval`]).
    pub speedup_interval: Option<[f64; 2]>,
    /// Its identical frames on the case.
    pub frames_identical: Option<usize>,
    /// Frames of the case the renderer rendered, over every run.
    pub frames: usize,
}

impl Violation {
    /// Frames that differ, or a slowdown the noise does not explain.
    pub fn beyond_noise(&self) -> bool {
        self.kind == ViolationKind::FramesDiffer || self.significant
    }
}

/// Coverage of [`speedup_interval`].
pub const INTERVAL: f64 = 0.9;
/// Resamples of [`speedup_interval`].
const RESAMPLES: usize = 2000;

/// The [`INTERVAL`] percentile-bootstrap interval of a renderer's speedup over `zbuffer` on a
/// case: frames are resampled in pairs (frame `i` of both was rendered moments apart, from the
/// same view: the suite interleaves renderers frame by frame), and each resample's speedup is
/// its sum of `zbuffer`'s times over its sum of the renderer's. Deterministic (a fixed seed),
/// so a report reproduces from its frame times. `None` for fewer than two frames, or frame
/// lists of different lengths.
pub fn speedup_interval(zbuffer_ms: &[f64], renderer_ms: &[f64]) -> Option<[f64; 2]> {
    let n = zbuffer_ms.len();
    if n < 2 || renderer_ms.len() != n {
        return None;
    }
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = move || {
        // splitmix64
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let mut speedups: Vec<f64> = (0..RESAMPLES)
        .map(|_| {
            let (mut z, mut r) = (0.0, 0.0);
            for _ in 0..n {
                let i = (next() % n as u64) as usize;
                z += zbuffer_ms[i];
                r += renderer_ms[i];
            }
            z / r.max(f64::MIN_POSITIVE)
        })
        .collect();
    speedups.sort_by(f64::total_cmp);
    let tail = (1.0 - INTERVAL) / 2.0;
    let at = |q: f64| speedups[((q * RESAMPLES as f64) as usize).min(RESAMPLES - 1)];
    Some([at(tail), at(1.0 - tail)])
}

/// `interval` widened to hold each of `runs`' speedups: a slowdown beyond noise must be
/// one in every run.
fn widened(interval: [f64; 2], runs: &[f64]) -> [f64; 2] {
    runs.iter().fold(interval, |[lo, hi], &s| [lo.min(s), hi.max(s)])
}

/// `num / den`, when `den` is positive and `num` finite (as the comparison's ratios).
fn ratio(num: f64, den: f64) -> Option<f64> {
    (den > 0.0 && num.is_finite()).then(|| num / den)
}

/// The case where a ratio was worst, and its value.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Worst {
    /// The case.
    pub case: String,
    /// The ratio there.
    pub value: f64,
}

/// One renderer over every case it ran.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RendererSummary {
    /// The renderer's label.
    pub name: String,
    /// Its frames must be identical to the reference's.
    pub conservative: bool,
    /// Cases it ran.
    pub cases: usize,
    /// Geometric mean of its speedup over `zbuffer` over the cases that measured one.
    pub speedup_geomean: Option<f64>,
    /// Its lowest speedup over `zbuffer`.
    pub speedup_worst: Option<Worst>,
    /// Geometric mean of its ratio to the oracle.
    pub oracle_geomean: Option<f64>,
    /// Its highest ratio to the oracle.
    pub oracle_worst: Option<Worst>,
    /// Frames identical to the reference's, over every case that checked them; `None` when
    /// none did.
    pub frames_identical: Option<usize>,
    /// Frames rendered, over every case.
    pub frames: usize,
    /// Its violations (see [`Violation`]).
    pub violations: usize,
    /// Those of them beyond the noise ([`Violation::significant`]).
    pub significant_violations: usize,
}

/// A case left out, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SkippedCase {
    /// The case.
    pub name: String,
    /// Its scene.
    pub scene: CaseScene,
    /// The model file looked for, when there was a folder to look in.
    pub path: Option<String>,
    /// Why.
    pub reason: String,
}

impl SkippedCase {
    pub(super) fn new(case: &Case, path: Option<&Path>, reason: &str) -> Self {
        Self {
            name: case.name.to_string(),
            scene: case.scene,
            path: path.map(|p| p.display().to_string()),
            reason: reason.to_string(),
        }
    }
}

/// Everything a suite run measured. Serializes to JSON (the CLI's `suite --json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SuiteReport {
    /// [`SUITE_VERSION`] of the definition run.
    pub suite_version: u32,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Rasterizer worker threads.
    pub threads: usize,
    /// The renderers requested, by label.
    pub algorithms: Vec<String>,
    /// The models folder, when one was given.
    pub models: Option<String>,
    /// The cases run, in order.
    pub cases: Vec<CaseReport>,
    /// The cases skipped.
    pub skipped: Vec<SkippedCase>,
    /// Per renderer, in the order it first appeared.
    pub summary: Vec<RendererSummary>,
    /// Every violation, case by case.
    pub violations: Vec<Violation>,
    /// How many violations (the length of `violations`): 0 when every conservative renderer
    /// was at least as fast as `zbuffer` with identical frames on every case.
    pub violation_count: usize,
    /// How many of them are beyond the noise: frames that differ, and speedups whose interval
    /// lies wholly below 1.
    pub significant_violation_count: usize,
    /// Wall time of the run, seconds.
    pub seconds: f64,
}

impl SuiteReport {
    /// The report of a run of `config` over the cases `done`, with `skipped` left out.
    pub(super) fn new(config: &SuiteConfig, done: Vec<CaseReport>, skipped: Vec<SkippedCase>) -> Self {
        let violations: Vec<Violation> = done.iter().flat_map(|c| c.violations.iter().cloned()).collect();
        Self {
            suite_version: SUITE_VERSION,
            width: config.width,
            height: config.height,
            threads: done.first().map_or_else(
                || match config.options.raster.threads {
                    0 => rayon::current_num_threads(),
                    n => n,
                },
                |c| c.compare.threads,
            ),
            algorithms: config.algorithms.iter().map(|a| a.label()).collect(),
            models: config.models.as_ref().map(|m| m.display().to_string()),
            summary: summarize(&done),
            violation_count: violations.len(),
            significant_violation_count: violations.iter().filter(|v| v.beyond_noise()).count(),
            violations,
            seconds: done.iter().map(|c| c.seconds).sum(),
            cases: done,
            skipped,
        }
    }

    /// The summary of the renderer called `name`.
    pub fn renderer(&self, name: &str) -> Option<&RendererSummary> {
        self.summary.iter().find(|r| r.name == name)
    }
}

/// Per renderer (in order of first appearance): geometric means and worst cases.
fn summarize(cases: &[CaseReport]) -> Vec<RendererSummary> {
    let mut names: Vec<&str> = Vec::new();
    for r in cases.iter().flat_map(|c| &c.renderers) {
        if !names.contains(&r.name.as_str()) {
            names.push(r.name.as_str());
        }
    }
    names
        .into_iter()
        .map(|name| {
            let runs: Vec<(&str, &CaseRenderer)> = cases
                .iter()
                .filter_map(|c| c.renderer(name).map(|r| (c.name.as_str(), r)))
                .collect();
            let speedups: Vec<(&str, f64)> = runs
                .iter()
                .filter_map(|(c, r)| r.speedup_vs_zbuffer.map(|s| (*c, s)))
                .collect();
            let oracle: Vec<(&str, f64)> = runs.iter().filter_map(|(c, r)| r.vs_oracle.map(|s| (*c, s))).collect();
            let checked: Vec<usize> = runs.iter().filter_map(|(_, r)| r.frames_identical).collect();
            RendererSummary {
                name: name.to_string(),
                conservative: runs.iter().all(|(_, r)| r.conservative),
                cases: runs.len(),
                speedup_geomean: geomean(&speedups),
                speedup_worst: worst(&speedups, |a, b| a < b),
                oracle_geomean: geomean(&oracle),
                oracle_worst: worst(&oracle, |a, b| a > b),
                frames_identical: (!checked.is_empty()).then(|| checked.iter().sum()),
                frames: runs.iter().map(|(_, r)| r.frames).sum(),
                violations: runs.iter().map(|(_, r)| r.violations().len()).sum(),
                significant_violations: runs
                    .iter()
                    .map(|(_, r)| {
                        r.violations()
                            .into_iter()
                            .filter(|&k| k == ViolationKind::FramesDiffer || r.significantly_slower())
                            .count()
                    })
                    .sum(),
            }
        })
        .collect()
}

/// The geometric mean of the positive, finite values; `None` when there is none.
fn geomean(values: &[(&str, f64)]) -> Option<f64> {
    let logs: Vec<f64> = values
        .iter()
        .map(|(_, v)| *v)
        .filter(|v| *v > 0.0 && v.is_finite())
        .map(f64::ln)
        .collect();
    (!logs.is_empty()).then(|| (logs.iter().sum::<f64>() / logs.len() as f64).exp())
}

/// The value for which `worse(value, every other)` holds (the first such), with its case.
fn worst(values: &[(&str, f64)], worse: fn(f64, f64) -> bool) -> Option<Worst> {
    values
        .iter()
        .copied()
        .reduce(|w, x| if worse(x.1, w.1) { x } else { w })
        .map(|(case, value)| Worst {
            case: case.to_string(),
            value,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometric_means_skip_what_is_not_a_ratio() {
        assert_eq!(geomean(&[]), None);
        assert_eq!(geomean(&[("a", 0.0), ("b", f64::NAN)]), None);
        let g =
            geomean(&[("a", 2.0), ("b", 8.0), ("c", f64::INFINITY)]).expect("two finite ratios have a geometric mean");
        assert!((g - 4.0).abs() < 1e-12, "{g}");
    }

    #[test]
    fn worst_is_the_first_extreme() {
        let v = [("a", 2.0), ("b", 0.5), ("c", 0.5), ("d", 3.0)];
        assert_eq!(
            worst(&v, |a, b| a < b)
                .expect("a non-empty list has a worst entry")
                .case,
            "b"
        );
        assert_eq!(
            worst(&v, |a, b| a > b)
                .expect("a non-empty list has a worst entry")
                .case,
            "d"
        );
        assert_eq!(worst(&[], |a, b| a < b), None);
    }

    #[test]
    fn only_conservative_renderers_owe_speed_and_identity() {
        let mut r = CaseRenderer {
            name: "x".into(),
            conservative: true,
            is_reference: false,
            mean_ms: 2.0,
            speedup_vs_zbuffer: Some(0.99),
            speedup_runs: vec![0.99],
            speedup_interval: Some([0.9, 1.05]),
            vs_oracle: Some(3.0),
            frames_identical: Some(3),
            frames: 4,
            direct_frames: 1,
            triangles_rasterized: 10.0,
            triangles_visible: 5.0,
        };
        assert_eq!(
            r.violations(),
            [ViolationKind::SlowerThanZbuffer, ViolationKind::FramesDiffer]
        );
        assert!(!r.significantly_slower(), "within the noise");
        r.speedup_interval = Some([0.9, 0.98]);
        assert!(r.significantly_slower());
        r.speedup_vs_zbuffer = Some(1.0);
        r.frames_identical = Some(4);
        assert!(r.violations().is_empty());
        r.speedup_vs_zbuffer = None;
        r.frames_identical = None;
        assert!(r.violations().is_empty(), "nothing measured, nothing broken");
        r.conservative = false;
        r.speedup_vs_zbuffer = Some(0.1);
        r.frames_identical = Some(0);
        assert!(r.violations().is_empty());
    }

    /// Several runs: a slowdown is beyond noise only when every run was slower, whatever the
    /// pooled frames' interval says.
    #[test]
    fn a_run_at_or_above_one_keeps_a_slowdown_within_noise() {
        let pooled = [0.90, 0.97];
        let r = |runs: &[f64]| CaseRenderer {
            name: "x".into(),
            conservative: true,
            is_reference: false,
            mean_ms: 2.0,
            speedup_vs_zbuffer: Some(0.95),
            speedup_runs: runs.to_vec(),
            speedup_interval: Some(widened(pooled, runs)),
            vs_oracle: None,
            frames_identical: None,
            frames: 9,
            direct_frames: 0,
            triangles_rasterized: 0.0,
            triangles_visible: 0.0,
        };
        assert!(!r(&[0.92, 1.01, 0.93]).significantly_slower(), "one run was faster");
        assert!(r(&[0.92, 0.95, 0.93]).significantly_slower());
        assert_eq!(widened(pooled, &[0.85, 0.93]), [0.85, 0.97]);
    }

    /// The interval holds the speedup of the frames as measured; a renderer slower on every
    /// frame lies wholly below 1; one slow frame among many does not make a slowdown certain.
    #[test]
    fn speedup_intervals_tell_noise_from_slowdowns() {
        let z = [10.0, 12.0, 9.0, 11.0, 10.0, 13.0, 10.0, 9.0];
        let same = speedup_interval(&z, &z).expect("eight frames each");
        assert!(same[0] == 1.0 && same[1] == 1.0, "{same:?}");
        let slower: Vec<f64> = z.iter().map(|t| t * 1.2).collect();
        let [lo, hi] = speedup_interval(&z, &slower).expect("eight frames each");
        assert!(
            lo <= 1.0 / 1.2 + 1e-9 && (1.0 / 1.2 - 1e-9..1.0).contains(&hi),
            "{lo} {hi}"
        );
        let mut spike = z.to_vec();
        spike[3] = 30.0;
        let [lo, hi] = speedup_interval(&z, &spike).expect("eight frames each");
        let point = z.iter().sum::<f64>() / spike.iter().sum::<f64>();
        assert!(point < 1.0 && lo < point && hi >= 1.0, "{lo} {point} {hi}");
        assert_eq!(
            speedup_interval(&z, &spike),
            speedup_interval(&z, &spike),
            "deterministic"
        );
        assert_eq!(speedup_interval(&z[..1], &z[..1]), None);
        assert_eq!(speedup_interval(&z, &z[..4]), None);
    }
}
