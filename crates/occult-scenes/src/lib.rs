//! # occult-scenes
//!
//! Where scenes come from: file loaders (OBJ, PLY, glTF/GLB), procedural generators that reach
//! 10^14 triangle instances through instancing, scene specs (`city:blocks=32` or a path), and
//! camera paths (`circle:N`, `street:N`, `flyover:N`, a JSON file of views).
#![deny(missing_docs)]

pub mod generate;
pub mod load;
pub mod path;
pub mod spec;
