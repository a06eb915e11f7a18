//! Camera paths.
