//! The integration tests of occult-scenes, one test binary (one module per subject): the
//! generators, the file loaders, the real models of `OCCULT_MODELS`, and camera paths.

mod generators;
mod loaders;
mod meshopt;
mod models;
mod paths;
