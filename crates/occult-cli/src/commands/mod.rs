//! One module per subcommand: each turns its validated arguments into library calls and
//! writes what they return.

pub mod algos;
pub mod compare;
pub mod info;
pub mod particles;
pub mod render;
pub mod scenes;
pub mod shadows;
pub mod sweep;
pub mod walk;
