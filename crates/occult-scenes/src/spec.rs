//! Scene specs: the one string by which the CLI (and tests, and benchmarks) name a scene.
//!
//! A spec is either a generator, `name` or `name:key=value,key=value` (`city:blocks=32`,
//! `terrain:g=724`, `forest:replicate=73,levels=2`), or a file path handed to
//! [`crate::load::load_file`]. Generator names win: `city` is always the generator. Anything else
//! is a file when it contains `/` or `\`, has an extension (`bunny.ply`), or exists; otherwise it
//! is an unknown generator, and the error lists the valid ones.
//!
//! Integer values may be written `1000000`, `1_000_000` or `1e6`. Parameters are checked
//! (ranges, memory and item-id bounds) when the spec is parsed, so a bad spec fails before
//! anything is built.
//!
//! ```
//! use occult_scenes::spec::parse_spec;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let built = parse_spec("terrain:g=2")?.build()?;
//! assert_eq!(built.scene.item_count(), 8);
//! assert_eq!(built.name, "terrain:g=2");
//! assert!(parse_spec("city:blocks=0").unwrap_err().to_string().contains("blocks"));
//! # Ok(())
//! # }
//! ```

use crate::generate::{GenerateError, Generator, GENERATORS};
pub use crate::generate::{GeneratorInfo, ParamInfo};
use crate::load::{load_file, LoadError};
use crate::path::framing_camera;
use occult_core::{Camera, Scene, Vec3};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A parsed scene spec.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSpec {
    /// A procedural generator with its parameters.
    Generator(Generator),
    /// A model file.
    File(PathBuf),
}

/// A built scene with what the CLI needs to show it.
#[derive(Clone, Debug)]
pub struct BuiltScene {
    /// The scene.
    pub scene: Scene,
    /// A short name for reports: the spec as given for generators, the file name for files.
    pub name: String,
    /// The generator's default view, or for files a view framing the bounds from the front
    /// (−z side), 25° above.
    pub default_camera: Camera,
    /// What a loader read but did not use (empty for generators).
    pub warnings: Vec<String>,
}

/// A spec that cannot be parsed or built.
#[derive(Debug, Error)]
pub enum SpecError {
    /// The spec is empty.
    #[error("empty scene spec; expected a generator ({valid}) or a model file path")]
    Empty {
        /// The generators, comma-separated.
        valid: String,
    },
    /// Neither a generator nor a file.
    #[error("unknown scene '{name}': not a generator ({valid}) nor a file path (.obj, .ply, .gltf, .glb)")]
    UnknownGenerator {
        /// The name given.
        name: String,
        /// The generators, comma-separated.
        valid: String,
    },
    /// A setting that is not `key=value`.
    #[error("malformed setting '{setting}' in scene spec '{spec}': expected key=value (keys: {valid})")]
    Malformed {
        /// The whole spec.
        spec: String,
        /// The offending setting.
        setting: String,
        /// The generator's keys, comma-separated.
        valid: String,
    },
    /// A key given twice.
    #[error("parameter '{key}' given twice in scene spec '{spec}'")]
    Duplicate {
        /// The whole spec.
        spec: String,
        /// The key.
        key: String,
    },
    /// A generator refused its parameters (unknown key, bad value, too large).
    #[error(transparent)]
    Generate(#[from] GenerateError),
    /// A file could not be loaded.
    #[error(transparent)]
    Load(#[from] LoadError),
}

/// All generators with their descriptions and parameter tables (for `occult scenes`).
pub fn generators() -> &'static [GeneratorInfo] {
    &GENERATORS
}

fn generator_names() -> String {
    GENERATORS.iter().map(|g| g.name).collect::<Vec<_>>().join(", ")
}

/// Parses a scene spec (see the module doc). Generator parameters are fully checked here;
/// files are only checked when built.
///
/// # Errors
/// [`SpecError::Empty`], [`SpecError::UnknownGenerator`], [`SpecError::Malformed`],
/// [`SpecError::Duplicate`], and [`SpecError::Generate`] for an unknown key, a value that does
/// not parse or is out of range, or a scene over the memory bound.
pub fn parse_spec(spec: &str) -> Result<SceneSpec, SpecError> {
    let spec = spec.trim();
    if spec.is_empty() {
        return Err(SpecError::Empty {
            valid: generator_names(),
        });
    }
    let (head, settings) = match spec.split_once(':') {
        Some((h, s)) => (h.trim(), Some(s)),
        None => (spec, None),
    };
    if let Some(mut generator) = Generator::from_name(head) {
        let valid = || generator_keys(head);
        let mut seen: Vec<&str> = Vec::new();
        for setting in settings
            .unwrap_or("")
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
        {
            let Some((key, value)) = setting.split_once('=') else {
                return Err(SpecError::Malformed {
                    spec: spec.to_string(),
                    setting: setting.to_string(),
                    valid: valid(),
                });
            };
            let key = key.trim();
            if key.is_empty() || value.trim().is_empty() {
                return Err(SpecError::Malformed {
                    spec: spec.to_string(),
                    setting: setting.to_string(),
                    valid: valid(),
                });
            }
            if seen.contains(&key) {
                return Err(SpecError::Duplicate {
                    spec: spec.to_string(),
                    key: key.to_string(),
                });
            }
            seen.push(key);
            generator.set(key, value.trim())?;
        }
        generator.validate()?;
        return Ok(SceneSpec::Generator(generator));
    }
    let path = Path::new(spec);
    if spec.contains('/') || spec.contains('\\') || path.extension().is_some() || path.exists() {
        return Ok(SceneSpec::File(path.to_path_buf()));
    }
    Err(SpecError::UnknownGenerator {
        name: head.to_string(),
        valid: generator_names(),
    })
}

fn generator_keys(name: &str) -> String {
    GENERATORS
        .iter()
        .find(|g| g.name == name)
        .map(|g| g.params.iter().map(|p| p.name).collect::<Vec<_>>().join(", "))
        .unwrap_or_default()
}

impl SceneSpec {
    /// A short name: `city:blocks=32` style for generators (non-default parameters only, in
    /// table order), the file name for files.
    pub fn name(&self) -> String {
        match self {
            Self::Generator(g) => {
                let default = Generator::from_name(g.name());
                let changed: Vec<String> = g
                    .info()
                    .params
                    .iter()
                    .filter_map(|p| {
                        let value = g.param(p.name)?;
                        let default_value = default.as_ref().and_then(|d| d.param(p.name));
                        (Some(&value) != default_value.as_ref()).then(|| format!("{}={value}", p.name))
                    })
                    .collect();
                if changed.is_empty() {
                    g.name().to_string()
                } else {
                    format!("{}:{}", g.name(), changed.join(","))
                }
            }
            Self::File(path) => path
                .file_name()
                .map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()),
        }
    }

    /// Builds (generates or loads) the scene.
    ///
    /// # Errors
    /// [`SpecError::Generate`] when a generator refuses its parameters; [`SpecError::Load`] when
    /// a file is missing, malformed or unsupported.
    pub fn build(&self) -> Result<BuiltScene, SpecError> {
        match self {
            Self::Generator(g) => {
                let scene = g.generate()?;
                let default_camera = g.default_camera(&scene);
                Ok(BuiltScene {
                    default_camera,
                    name: self.name(),
                    scene,
                    warnings: Vec::new(),
                })
            }
            Self::File(path) => {
                let loaded = load_file(path)?;
                let default_camera = framing_camera(&loaded.scene.bounds(), Vec3::new(0.0, 0.42, -0.9), 60.0);
                Ok(BuiltScene {
                    scene: loaded.scene,
                    name: self.name(),
                    default_camera,
                    warnings: loaded.warnings,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::{CityParams, ForestParams, TerrainParams};

    #[test]
    fn bare_names_are_generators_with_defaults() {
        assert_eq!(
            parse_spec("city").expect("a bare generator name parses"),
            SceneSpec::Generator(Generator::City(CityParams::default()))
        );
        assert_eq!(
            parse_spec("  terrain ").expect("a padded generator name parses"),
            SceneSpec::Generator(Generator::Terrain(TerrainParams::default()))
        );
        assert_eq!(
            parse_spec("city:").expect("a name with an empty setting list parses"),
            SceneSpec::Generator(Generator::City(CityParams::default()))
        );
    }

    #[test]
    fn settings_are_applied() {
        let s = parse_spec("city:blocks=32, detail=2").expect("valid city settings parse");
        assert_eq!(
            s,
            SceneSpec::Generator(Generator::City(CityParams {
                blocks: 32,
                detail: 2,
                ..Default::default()
            }))
        );
        let f = parse_spec("forest:replicate=73,levels=2").expect("valid forest settings parse");
        assert_eq!(
            f,
            SceneSpec::Generator(Generator::Forest(ForestParams::replicated_1e14()))
        );
        assert_eq!(
            parse_spec("terrain:g=1e3").expect("an integer in e notation parses"),
            SceneSpec::Generator(Generator::Terrain(TerrainParams { g: 1000, tiles: 1 }))
        );
    }

    #[test]
    fn names_list_changed_parameters_only() {
        assert_eq!(parse_spec("city").expect("a bare generator name parses").name(), "city");
        assert_eq!(
            parse_spec("city:detail=2,blocks=3,seed=1")
                .expect("valid city settings parse")
                .name(),
            "city:blocks=3,detail=2"
        );
        assert_eq!(
            parse_spec("models/bunny.ply")
                .expect("a path parses as a file spec")
                .name(),
            "bunny.ply"
        );
    }

    #[test]
    fn paths_are_files() {
        for p in ["models/bunny.ply", "bunny.obj", "./x", "C:\\m\\a", "scene.glb"] {
            assert!(
                matches!(parse_spec(p).expect("a path parses as a file spec"), SceneSpec::File(_)),
                "{p}"
            );
        }
    }

    #[test]
    fn unknown_generator_lists_the_valid_ones() {
        let e = parse_spec("cty:blocks=3").unwrap_err();
        assert!(matches!(e, SpecError::UnknownGenerator { .. }));
        let msg = e.to_string();
        for g in ["terrain", "city", "forest", "chessboard", "plant", "occluder"] {
            assert!(msg.contains(g), "{msg}");
        }
        assert!(!msg.contains('\n'));
        assert!(matches!(parse_spec("").unwrap_err(), SpecError::Empty { .. }));
        assert!(matches!(parse_spec("   ").unwrap_err(), SpecError::Empty { .. }));
    }

    #[test]
    fn bad_settings_are_errors_naming_the_problem() {
        let msg = |s: &str| parse_spec(s).unwrap_err().to_string();
        assert!(msg("city:blocks").contains("key=value"));
        assert!(msg("city:=3").contains("key=value"));
        assert!(msg("city:blocks=").contains("key=value"));
        assert!(msg("city:blocks=3,blocks=4").contains("twice"));
        let unknown = msg("city:floors=3");
        assert!(
            unknown.contains("floors") && unknown.contains("blocks, detail, variants, seed"),
            "{unknown}"
        );
        assert!(msg("city:blocks=-1").contains("blocks"));
        assert!(msg("city:blocks=x").contains("blocks"));
        assert!(msg("city:blocks=0").contains("blocks"));
        assert!(msg("terrain:g=99999999999").contains("'g'"));
        assert!(msg("terrain:g=60000").contains("reduce 'g'"));
        assert!(msg("chessboard:n=0").contains("'n'"));
        assert!(msg("forest:replicate=1000000,levels=8").contains("replicate"));
    }

    #[test]
    fn generator_table_is_complete() {
        let names: Vec<_> = generators().iter().map(|g| g.name).collect();
        assert_eq!(names, ["terrain", "city", "forest", "chessboard", "plant", "occluder"]);
        for g in generators() {
            assert!(!g.description.is_empty() && !g.params.is_empty());
            for p in g.params {
                assert!(!p.meaning.is_empty() && !p.default.is_empty());
            }
        }
    }

    #[test]
    fn missing_file_is_a_load_error() {
        let e = parse_spec("no/such/file.obj")
            .expect("a path parses as a file spec")
            .build()
            .unwrap_err();
        assert!(matches!(e, SpecError::Load(_)));
        assert!(e.to_string().contains("file.obj"));
    }
}
