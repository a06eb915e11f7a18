//! File loaders.
