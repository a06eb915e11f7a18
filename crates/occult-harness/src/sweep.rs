//! Parameter sweeps: one renderer parameter varied over a list of values, a full
//! [`compare`] per value (same scene, cameras and frame size), so that frame time and counters
//! can be plotted against the value: the figures of the papers that put a parameter on the x
//! axis (grid resolution, depth accuracy ε, leaf size...).
//!
//! Cost: one comparison per value; the scene is shared, the renderers are rebuilt per value.

use std::sync::Arc;

use occult_core::{Camera, Scene};
use occult_render::{AlgoSpec, RenderError, RenderOptions};
use thiserror::Error;

use crate::compare::{compare, CompareConfig, CompareError, CompareProgress, CompareReport, Reference, RendererReport};

/// The parameter varied: `key` of every spec of `algorithm`, set to each of `values` in turn.
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    /// Algorithm name whose specs get the key.
    pub algorithm: String,
    /// Parameter key.
    pub key: String,
    /// Values, in order; numbers, since they are the x axis.
    pub values: Vec<String>,
}

impl Vary {
    /// `label` without the varied setting (`oqgrid:res=20,batch=4` → `oqgrid:batch=4`), so that
    /// one renderer's points across values form one line.
    pub fn base_label(&self, label: &str) -> String {
        let Some((name, settings)) = label.split_once(':') else {
            return label.to_string();
        };
        if name != self.algorithm {
            return label.to_string();
        }
        let kept: Vec<&str> = settings
            .split(',')
            .filter(|s| s.split_once('=').map(|(k, _)| k) != Some(self.key.as_str()))
            .collect();
        if kept.is_empty() {
            name.to_string()
        } else {
            format!("{name}:{}", kept.join(","))
        }
    }
}

/// Errors of [`sweep`].
#[derive(Debug, Error)]
pub enum SweepError {
    /// The varied algorithm is not among the renderers compared.
    #[error("'{algorithm}' is not among the renderers compared ({lineup})")]
    NotInLineup {
        /// The varied algorithm.
        algorithm: String,
        /// The labels of the renderers compared, comma-separated.
        lineup: String,
    },
    /// A value is not a valid setting of the varied parameter.
    #[error(transparent)]
    BadValue(#[from] RenderError),
    /// The comparison at one value failed.
    #[error("sweeping {algorithm}.{key}={value}")]
    Compare {
        /// The varied algorithm.
        algorithm: String,
        /// The varied key.
        key: String,
        /// The value.
        value: String,
        /// Why.
        source: CompareError,
    },
}

/// What to sweep and how.
#[derive(Clone, Debug)]
pub struct SweepConfig {
    /// Renderers compared at every value; the varied algorithm must be among them.
    pub algorithms: Vec<AlgoSpec>,
    /// The parameter and its values.
    pub vary: Vary,
    /// Options every renderer is built with.
    pub options: RenderOptions,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// What frames are checked against, at every value.
    pub reference: Reference,
}

impl SweepConfig {
    /// The labels of [`SweepConfig::algorithms`], comma-separated.
    pub fn lineup_text(&self) -> String {
        self.algorithms
            .iter()
            .map(AlgoSpec::label)
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// One line-up per value: the varied algorithm's specs get `key=value`, each checked.
    /// Cheap; [`sweep`] calls it first, callers may call it to check a sweep before building
    /// the scene.
    ///
    /// # Errors
    /// [`SweepError::NotInLineup`], [`SweepError::BadValue`].
    pub fn lineups(&self) -> Result<Vec<Vec<AlgoSpec>>, SweepError> {
        let vary = &self.vary;
        if !self.algorithms.iter().any(|s| s.algorithm.name() == vary.algorithm) {
            return Err(SweepError::NotInLineup {
                algorithm: vary.algorithm.clone(),
                lineup: self.lineup_text(),
            });
        }
        let lineups = vary
            .values
            .iter()
            .map(|v| {
                self.algorithms
                    .iter()
                    .map(|s| {
                        let mut s = s.clone();
                        if s.algorithm.name() == vary.algorithm {
                            s.params.set(&vary.key, v);
                            s.validate()?;
                        }
                        Ok(s)
                    })
                    .collect::<Result<Vec<_>, RenderError>>()
            })
            .collect::<Result<_, _>>()?;
        Ok(lineups)
    }
}

/// Every counter any renderer of `algorithms` can report (with repeats).
pub fn counter_names<'a>(algorithms: impl IntoIterator<Item = &'a AlgoSpec>) -> Vec<&'static str> {
    algorithms
        .into_iter()
        .flat_map(|s| s.algorithm.counter_names())
        .collect()
}

/// Progress of a sweep: the value being compared and the comparison's own event.
pub type SweepProgress<'a> = (&'a str, CompareProgress<'a>);

/// One value's comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepPoint {
    /// The value, as given.
    pub value: String,
    /// The comparison at that value.
    pub report: CompareReport,
}

/// Everything [`sweep`] measured: one point per value, in order.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepReport {
    /// The points.
    pub points: Vec<SweepPoint>,
}

/// One renderer's measure across the values: a line of a plot.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepLine {
    /// The renderer's label without the varied setting ([`Vary::base_label`]).
    pub name: String,
    /// (value, measure) for each value where the renderer reported the measure.
    pub points: Vec<(f64, f64)>,
}

impl SweepReport {
    /// Per renderer (in order of first appearance), `measure` of its report at every value
    /// where it has one, against the value (values that are not numbers give NaN); renderers
    /// without any point are left out.
    pub fn lines(&self, vary: &Vary, measure: &dyn Fn(&RendererReport) -> Option<f64>) -> Vec<SweepLine> {
        let xs: Vec<f64> = self
            .points
            .iter()
            .map(|p| p.value.parse().unwrap_or(f64::NAN))
            .collect();
        let mut names: Vec<String> = Vec::new();
        for p in &self.points {
            for x in &p.report.renderers {
                let name = vary.base_label(&x.name);
                if !names.contains(&name) {
                    names.push(name);
                }
            }
        }
        names
            .into_iter()
            .map(|name| SweepLine {
                points: xs
                    .iter()
                    .zip(&self.points)
                    .filter_map(|(&x, p)| {
                        p.report
                            .renderers
                            .iter()
                            .find(|c| vary.base_label(&c.name) == name)
                            .and_then(measure)
                            .map(|y| (x, y))
                    })
                    .collect(),
                name,
            })
            .filter(|l| !l.points.is_empty())
            .collect()
    }
}

/// Compares the renderers of `config` over `cameras` on `scene` once per value of
/// [`SweepConfig::vary`]; `progress` hears every comparison's events with the value.
///
/// # Errors
/// Those of [`SweepConfig::lineups`], then [`SweepError::Compare`] naming the value whose
/// comparison failed.
pub fn sweep(
    scene: &Arc<Scene>,
    cameras: &[Camera],
    config: &SweepConfig,
    progress: &mut dyn FnMut(SweepProgress),
) -> Result<SweepReport, SweepError> {
    let vary = &config.vary;
    let mut points = Vec::with_capacity(vary.values.len());
    for (value, algorithms) in vary.values.iter().zip(config.lineups()?) {
        let compare_config = CompareConfig {
            algorithms,
            options: config.options.clone(),
            width: config.width,
            height: config.height,
            reference: config.reference.clone(),
            image_complexity: false,
            peak_rss: None,
            diff_images: false,
        };
        let report = compare(Arc::clone(scene), cameras, &compare_config, &mut |event| {
            progress((value, event))
        })
        .map_err(|source| SweepError::Compare {
            algorithm: vary.algorithm.clone(),
            key: vary.key.clone(),
            value: value.clone(),
            source,
        })?;
        points.push(SweepPoint {
            value: value.clone(),
            report,
        });
    }
    Ok(SweepReport { points })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vary(algorithm: &str, key: &str) -> Vary {
        Vary {
            algorithm: algorithm.into(),
            key: key.into(),
            values: vec!["8".into(), "16".into()],
        }
    }

    #[test]
    fn lines_are_named_without_the_varied_value() {
        let v = vary("frustum", "leaf");
        assert_eq!(v.base_label("frustum:leaf=8"), "frustum");
        assert_eq!(v.base_label("frustum:group_leaf=2,leaf=8"), "frustum:group_leaf=2");
        assert_eq!(v.base_label("zbuffer"), "zbuffer");
        assert_eq!(v.base_label("frustum:group_leaf=2"), "frustum:group_leaf=2");
    }

    #[test]
    fn lineups_set_the_value_and_check_it() {
        let mut config = SweepConfig {
            algorithms: vec![
                AlgoSpec::parse("zbuffer").expect("zbuffer is a known renderer"),
                AlgoSpec::parse("frustum").expect("frustum is a known renderer"),
            ],
            vary: vary("frustum", "leaf"),
            options: RenderOptions::default(),
            width: 32,
            height: 32,
            reference: Reference::Auto,
        };
        let lineups = config.lineups().expect("frustum has a leaf parameter to vary");
        let labels: Vec<Vec<String>> = lineups
            .iter()
            .map(|l| l.iter().map(AlgoSpec::label).collect())
            .collect();
        assert_eq!(labels, [["zbuffer", "frustum:leaf=8"], ["zbuffer", "frustum:leaf=16"]]);
        config.vary.values = vec!["0".into()];
        assert!(matches!(config.lineups(), Err(SweepError::BadValue(_))));
        config.vary = vary("hzb", "leaf");
        assert!(matches!(config.lineups(), Err(SweepError::NotInLineup { .. })));
    }
}
