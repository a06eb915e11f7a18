//! Procedural scene generators: one file per scene, each a `generate(&Params)` function that
//! returns a [`Scene`] and a `default_camera(&Params, &Scene)` that frames it.
//!
//! | generator | what | default size (triangle instances) |
//! | --- | --- | --- |
//! | [`terrain`] | the anchor benchmark heightfield, tiled | 1,048,352 (`tiles=10`: 1.05·10^8) |
//! | [`city`] | streets and blocks of windowed buildings, densely occluded | ≈ 2.0 M (`blocks=64`: 1.2·10^8) |
//! | [`forest`] | fractal terrain with instanced 19.5k-triangle trees, nested replication | 5,000,192 (`replicate=73,levels=2`: 1.42·10^14) |
//! | [`chessboard`] | n × n squares of constant projected area (Wand et al. §8.1) | 2,097,152 (`n=10000000`: 2·10^14) |
//! | [`plant`] | power-plant interior: floors, walls with openings, pipes, tanks | ≈ 2.3 M (`units=28`: 1.1·10^8) |
//! | [`occluder`] | a wall in front of tessellated spheres (Georges et al. §5.2) | 1,612,812 (`objects=100`: 1.6·10^8) |
//!
//! # Design
//! - **Instancing reaches the size; unique geometry stays small.** Every generator builds a few
//!   unique meshes (building variants, tree variants, plant units, a chessboard block) and
//!   places them through the scene DAG. Large grids are nested (a row group, then a group of
//!   rows, see `shapes::grid`) so that stored instances grow with the side of the grid, not its
//!   area. This is how the forest reaches 1.4·10^14 triangles in a few megabytes (randomized
//!   z-buffer paper, §7.3 and §8.6).
//! - **Checked before allocated.** Each generator validates its parameters (a zero or absurd
//!   value is [`GenerateError::BadParameter`] naming it) and estimates the bytes of unique
//!   geometry and instances it would store; above [`MAX_UNIQUE_BYTES`] it refuses with
//!   [`GenerateError::TooLarge`] before allocating anything. Item counts past the 64-bit id
//!   space are refused the same way.
//! - **Readable.** Every mesh carries colors ([`occult_core::MeshColors`]): per object class
//!   (facade, glass, trunk, leaves, pipe) so that frames can be read by eye.
//! - **Deterministic.** Randomness comes from a seeded PCG per unique mesh, so parallel builds
//!   (rayon, one task per variant) produce the same scene for the same parameters.
//!
//! [`Generator`] is the closed set of generators, chosen at run time by name (`city`) with
//! `key=value` settings; [`GENERATORS`] describes them for `occult scenes`.

/// Declares a generator's parameter struct from one table, each field with its doc, its name
/// (which is also its key in a spec), its type (`u32` or `u64`) and its default; implements
/// `Default` from those defaults and `slot`, the [`ParamSlot`] lookup by key behind
/// [`Generator::set`] and [`Generator::param`]. The struct's own attributes pass through.
macro_rules! generator_params {
    (
        $(#[$struct_meta:meta])*
        pub struct $name:ident {
            $(
                $(#[$field_meta:meta])*
                pub $field:ident: $ty:ty = $default:expr,
            )+
        }
    ) => {
        $(#[$struct_meta])*
        pub struct $name {
            $(
                $(#[$field_meta])*
                pub $field: $ty,
            )+
        }

        impl Default for $name {
            fn default() -> Self {
                Self { $($field: $default,)+ }
            }
        }

        impl $name {
            /// Where [`super::Generator::set`] writes parameter `key`.
            pub(crate) fn slot(&mut self, key: &str) -> super::ParamSlot<'_> {
                match key {
                    $(stringify!($field) => super::ParamSlot::from(&mut self.$field),)+
                    _ => super::ParamSlot::Unknown,
                }
            }
        }
    };
}

pub mod chessboard;
pub mod city;
pub mod forest;
pub mod occluder;
pub mod plant;
mod shapes;
pub mod terrain;

pub use chessboard::ChessboardParams;
pub use city::CityParams;
pub use forest::ForestParams;
pub use occluder::OccluderParams;
pub use plant::PlantParams;
pub use terrain::TerrainParams;

use occult_core::{Camera, CoreError, Scene};
use thiserror::Error;

/// Largest estimated memory of a generated scene's stored geometry and instances, in bytes.
/// Parameters that would exceed it are refused before anything is allocated. 4 GiB leaves room
/// for the renderers' own structures (octrees, grids) on a 16–32 GB machine; raising it trades
/// that headroom for bigger unique geometry (instancing rarely needs it).
pub const MAX_UNIQUE_BYTES: u64 = 4 << 30;

/// A generator refused its parameters or could not build its scene.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GenerateError {
    /// No parameter of that name.
    #[error("{generator}: unknown parameter '{key}' (valid: {valid})")]
    UnknownParameter {
        /// The generator.
        generator: &'static str,
        /// The key given.
        key: String,
        /// The valid keys, comma-separated.
        valid: String,
    },
    /// A parameter value cannot be parsed or is out of its range.
    #[error("{generator}: bad value '{value}' for parameter '{parameter}': {reason}")]
    BadParameter {
        /// The generator.
        generator: &'static str,
        /// The parameter.
        parameter: String,
        /// The value given.
        value: String,
        /// Why it is refused (the accepted range).
        reason: String,
    },
    /// The parameters ask for more stored geometry than [`MAX_UNIQUE_BYTES`] (or for more
    /// triangle instances than 64-bit item ids can name).
    #[error("{generator}: {what}; reduce '{parameter}'")]
    TooLarge {
        /// The generator.
        generator: &'static str,
        /// The parameter most responsible.
        parameter: String,
        /// What would be exceeded, with the numbers.
        what: String,
    },
    /// The scene model refused what the generator built (a bug in the generator if it ever
    /// happens for accepted parameters).
    #[error("{generator}: {source}")]
    Scene {
        /// The generator.
        generator: &'static str,
        /// The scene model's error.
        #[source]
        source: CoreError,
    },
}

/// One parameter of a generator, for help text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamInfo {
    /// Key in a spec (`blocks` in `city:blocks=32`).
    pub name: &'static str,
    /// Default value, as it would be written in a spec.
    pub default: &'static str,
    /// What it means, its unit and its accepted range.
    pub meaning: &'static str,
}

/// A generator's name, one-line description and parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GeneratorInfo {
    /// Name in a spec (`city`).
    pub name: &'static str,
    /// One line: what the scene is and its default size.
    pub description: &'static str,
    /// Its parameters, in the order `occult scenes` lists them.
    pub params: &'static [ParamInfo],
}

/// All generators, in the order `occult scenes` lists them.
pub static GENERATORS: [GeneratorInfo; 6] = [
    terrain::INFO,
    city::INFO,
    forest::INFO,
    chessboard::INFO,
    plant::INFO,
    occluder::INFO,
];

/// A generator with its parameters: the closed set of procedural scenes.
#[derive(Clone, Debug, PartialEq)]
pub enum Generator {
    /// See [`terrain`].
    Terrain(TerrainParams),
    /// See [`city`].
    City(CityParams),
    /// See [`forest`].
    Forest(ForestParams),
    /// See [`chessboard`].
    Chessboard(ChessboardParams),
    /// See [`plant`].
    Plant(PlantParams),
    /// See [`occluder`].
    Occluder(OccluderParams),
}

impl Generator {
    /// The generator called `name`, with default parameters; `None` for an unknown name.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "terrain" => Self::Terrain(TerrainParams::default()),
            "city" => Self::City(CityParams::default()),
            "forest" => Self::Forest(ForestParams::default()),
            "chessboard" => Self::Chessboard(ChessboardParams::default()),
            "plant" => Self::Plant(PlantParams::default()),
            "occluder" => Self::Occluder(OccluderParams::default()),
            _ => return None,
        })
    }

    /// Its description and parameter table.
    pub fn info(&self) -> &'static GeneratorInfo {
        match self {
            Self::Terrain(_) => &GENERATORS[0],
            Self::City(_) => &GENERATORS[1],
            Self::Forest(_) => &GENERATORS[2],
            Self::Chessboard(_) => &GENERATORS[3],
            Self::Plant(_) => &GENERATORS[4],
            Self::Occluder(_) => &GENERATORS[5],
        }
    }

    /// Its name (`city`).
    pub fn name(&self) -> &'static str {
        self.info().name
    }

    /// The current value of parameter `key` as spec text; `None` for an unknown key.
    pub fn param(&self, key: &str) -> Option<String> {
        let mut copy = self.clone();
        let value = match copy.slot(key) {
            ParamSlot::U32(v) => v.to_string(),
            ParamSlot::U64(v) => v.to_string(),
            ParamSlot::Unknown => return None,
        };
        Some(value)
    }

    fn slot(&mut self, key: &str) -> ParamSlot<'_> {
        match self {
            Self::Terrain(p) => p.slot(key),
            Self::City(p) => p.slot(key),
            Self::Forest(p) => p.slot(key),
            Self::Chessboard(p) => p.slot(key),
            Self::Plant(p) => p.slot(key),
            Self::Occluder(p) => p.slot(key),
        }
    }

    /// Sets parameter `key` from its spec text. Values are parsed here and range-checked by
    /// [`Generator::generate`].
    ///
    /// # Errors
    /// [`GenerateError::UnknownParameter`] listing the valid keys;
    /// [`GenerateError::BadParameter`] for a value that does not parse.
    pub fn set(&mut self, key: &str, value: &str) -> Result<(), GenerateError> {
        let name = self.name();
        match self.slot(key) {
            ParamSlot::U32(v) => *v = parse_integer(name, key, value, u32::MAX as u64)? as u32,
            ParamSlot::U64(v) => *v = parse_integer(name, key, value, u64::MAX)?,
            ParamSlot::Unknown => {
                let valid = self.info().params.iter().map(|p| p.name).collect::<Vec<_>>().join(", ");
                return Err(GenerateError::UnknownParameter {
                    generator: name,
                    key: key.to_string(),
                    valid,
                });
            }
        }
        Ok(())
    }

    /// Checks the parameters (ranges, memory and item-id bounds) without building anything.
    ///
    /// # Errors
    /// As [`Generator::generate`].
    pub fn validate(&self) -> Result<(), GenerateError> {
        match self {
            Self::Terrain(p) => terrain::validate(p),
            Self::City(p) => city::validate(p),
            Self::Forest(p) => forest::validate(p),
            Self::Chessboard(p) => chessboard::validate(p),
            Self::Plant(p) => plant::validate(p),
            Self::Occluder(p) => occluder::validate(p),
        }
    }

    /// Builds the scene.
    ///
    /// # Errors
    /// [`GenerateError::BadParameter`] for a parameter out of range, [`GenerateError::TooLarge`]
    /// when the scene would exceed [`MAX_UNIQUE_BYTES`] or the item id space.
    pub fn generate(&self) -> Result<Scene, GenerateError> {
        match self {
            Self::Terrain(p) => terrain::generate(p),
            Self::City(p) => city::generate(p),
            Self::Forest(p) => forest::generate(p),
            Self::Chessboard(p) => chessboard::generate(p),
            Self::Plant(p) => plant::generate(p),
            Self::Occluder(p) => occluder::generate(p),
        }
    }

    /// The generator's default view of `scene` (which it built from these parameters).
    pub fn default_camera(&self, scene: &Scene) -> Camera {
        match self {
            Self::Terrain(p) => terrain::default_camera(p, scene),
            Self::City(p) => city::default_camera(p, scene),
            Self::Forest(p) => forest::default_camera(p, scene),
            Self::Chessboard(p) => chessboard::default_camera(p, scene),
            Self::Plant(p) => plant::default_camera(p, scene),
            Self::Occluder(p) => occluder::default_camera(p, scene),
        }
    }
}

/// Where [`Generator::set`] writes a parameter.
pub(crate) enum ParamSlot<'a> {
    U32(&'a mut u32),
    U64(&'a mut u64),
    Unknown,
}

impl<'a> From<&'a mut u32> for ParamSlot<'a> {
    fn from(value: &'a mut u32) -> Self {
        Self::U32(value)
    }
}

impl<'a> From<&'a mut u64> for ParamSlot<'a> {
    fn from(value: &'a mut u64) -> Self {
        Self::U64(value)
    }
}

/// Parses an unsigned integer written as `1000000`, `1_000_000` or `1e6`.
fn parse_integer(generator: &'static str, key: &str, value: &str, max: u64) -> Result<u64, GenerateError> {
    let bad = |reason: String| GenerateError::BadParameter {
        generator,
        parameter: key.to_string(),
        value: value.to_string(),
        reason,
    };
    let text: String = value.trim().chars().filter(|&c| c != '_').collect();
    let parsed = match text.parse::<u64>() {
        Ok(v) => v,
        Err(_) => match text.parse::<f64>() {
            Ok(f) if f.is_finite() && f >= 0.0 && f.fract() == 0.0 && f <= max as f64 => f as u64,
            _ => return Err(bad("not a non-negative integer".into())),
        },
    };
    if parsed > max {
        return Err(bad(format!("larger than {max}")));
    }
    Ok(parsed)
}

/// Checks `min <= value <= max` for parameter `name`.
pub(crate) fn check_range(
    generator: &'static str,
    name: &str,
    value: u64,
    min: u64,
    max: u64,
) -> Result<(), GenerateError> {
    if value < min || value > max {
        return Err(GenerateError::BadParameter {
            generator,
            parameter: name.to_string(),
            value: value.to_string(),
            reason: format!("must be in {min}..={max}"),
        });
    }
    Ok(())
}

/// Refuses a scene whose stored bytes exceed [`MAX_UNIQUE_BYTES`] or whose triangle instances do
/// not fit 64-bit item ids (`u64::MAX` itself is reserved for "no item"). Arithmetic is in
/// `u128`, so absurd parameters cannot overflow the check itself.
pub(crate) fn check_budget(
    generator: &'static str,
    parameter: &str,
    bytes: u128,
    items: u128,
) -> Result<(), GenerateError> {
    if bytes > MAX_UNIQUE_BYTES as u128 {
        return Err(GenerateError::TooLarge {
            generator,
            parameter: parameter.to_string(),
            what: format!("stored geometry would take about {bytes} bytes, over the limit of {MAX_UNIQUE_BYTES}"),
        });
    }
    if items >= u64::MAX as u128 {
        return Err(GenerateError::TooLarge {
            generator,
            parameter: parameter.to_string(),
            what: format!("about {items} triangle instances do not fit 64-bit item ids"),
        });
    }
    Ok(())
}

/// A 64-bit hash of a grid cell and a seed, for placement that does not depend on the order in
/// which cells are built (splitmix64 finalizer).
pub(crate) fn mix(seed: u64, i: u32, j: u32) -> u64 {
    let mut x = seed ^ ((i as u64) << 32 | j as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x ^= x >> 30;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 27;
    x = x.wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Wraps a scene-model error of `generator`.
pub(crate) fn scene_error(generator: &'static str) -> impl Fn(CoreError) -> GenerateError {
    move |source| GenerateError::Scene { generator, source }
}

/// A camera `eye → target` with +y up, 60° vertical fov, and near/far planes that hold the
/// whole of `scene` seen from `eye` (near at least `min_near`).
pub(crate) fn camera_for(scene: &Scene, eye: occult_core::Vec3, target: occult_core::Vec3, near: f32) -> Camera {
    let bounds = scene.bounds();
    let farthest = bounds.corners().iter().map(|c| c.distance(eye)).fold(0.0f32, f32::max);
    Camera {
        eye,
        target,
        up: occult_core::Vec3::Y,
        fov_y_deg: 60.0,
        near,
        far: (farthest * 1.05).max(near * 10.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_info_default_parses_to_the_default_params() {
        for info in &GENERATORS {
            let default = Generator::from_name(info.name).expect("every listed generator name is known");
            let mut g = default.clone();
            for p in info.params {
                g.set(p.name, p.default)
                    .expect("every listed default is a valid setting");
            }
            assert_eq!(g, default, "{}", info.name);
            assert_eq!(g.name(), info.name);
        }
    }

    #[test]
    fn integers_parse_in_three_spellings() {
        assert_eq!(
            parse_integer("t", "k", "1000000", u64::MAX).expect("a plain integer parses"),
            1_000_000
        );
        assert_eq!(
            parse_integer("t", "k", "1_000_000", u64::MAX).expect("an underscored integer parses"),
            1_000_000
        );
        assert_eq!(
            parse_integer("t", "k", "1e6", u64::MAX).expect("an integer in e notation parses"),
            1_000_000
        );
        for bad in ["", "-1", "1.5", "abc", "nan", "inf", "1e30"] {
            assert!(parse_integer("t", "k", bad, u32::MAX as u64).is_err(), "{bad}");
        }
        assert!(parse_integer("t", "k", "4294967296", u32::MAX as u64).is_err());
    }

    #[test]
    fn unknown_key_lists_the_valid_ones() {
        let mut g = Generator::from_name("city").expect("city is a known generator");
        let e = g.set("blokcs", "3").unwrap_err().to_string();
        assert!(e.contains("blocks") && e.contains("detail"), "{e}");
    }

    #[test]
    fn budget_refuses_overflow_and_bytes() {
        assert!(check_budget("t", "g", MAX_UNIQUE_BYTES as u128 + 1, 1).is_err());
        assert!(check_budget("t", "g", 1, u64::MAX as u128).is_err());
        assert!(check_budget("t", "g", 1, 1).is_ok());
    }
}
