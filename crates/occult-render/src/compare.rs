//! Comparison harness (in progress).
