//! The cross-renderer invariant tests, one test binary: DESIGN invariant 2 (conservative
//! renderers produce frames bit-identical to `zbuffer`) for every renderer and configuration,
//! over every generator with random views and over camera paths, plus each renderer's
//! end-to-end checks that need several renderers or real scenes (counters, errors, `rzb`'s
//! measured error), and the golden frames that pin `zbuffer` itself. One module per renderer; `support` holds the shared checks.

mod bands;
mod clusters;
mod frustum;
mod golden;
mod hzb;
mod lzb;
mod nbuffer;
mod nbuffer_shadows;
mod oqgrid;
mod rzb;
mod support;
