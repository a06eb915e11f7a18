//! Scene specs.
