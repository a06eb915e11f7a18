//! # occult-scenes
//!
//! Where scenes come from: file loaders (OBJ, PLY, glTF/GLB), procedural generators that reach
//! 10^14 triangle instances through instancing, scene specs (`city:blocks=32` or a path), and
//! camera paths (`circle:N`, `street:N`, `flyover:N`, a JSON file of views).
//!
//! - [`generate`]: `terrain` (the anchor benchmark), `city`, `forest`, `chessboard`, `plant`,
//!   `occluder`; each a params struct with `Default`, a `generate` function and a default camera.
//! - [`spec`]: [`parse_spec`] turns the one string the CLI takes into a [`SceneSpec`], whose
//!   [`SceneSpec::build`] gives a [`BuiltScene`] (scene, name, default camera, loader warnings).
//! - [`path`]: [`parse_path`] turns a path spec into views ([`PathSpec`] checks one before the
//!   scene exists, [`ViewSpec`] names one view); [`path::write_path_json`] saves them.
//! - [`load`]: [`load::load_file`] reads a model file.
//! - [`save`]: writes a mesh as OBJ, PLY or GLB (round trips, load benchmarks, fuzz seeds).
//!
//! ```
//! use occult_scenes::{parse_path, parse_spec};
//! let built = parse_spec("city:blocks=2,detail=1")?.build()?;
//! assert!(built.scene.item_count() > 10_000);
//! let views = parse_path("street:30", &built.scene, &built.default_camera)?;
//! assert_eq!(views.len(), 30);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

pub mod generate;
pub mod load;
pub mod path;
pub mod save;
pub mod spec;

pub use generate::{GenerateError, Generator, GeneratorInfo, ParamInfo};
pub use path::{parse_path, PathError, PathSpec, ViewSpec};
pub use spec::{generators, parse_spec, BuiltScene, SceneSpec, SpecError};
