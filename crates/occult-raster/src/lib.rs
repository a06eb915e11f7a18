//! # occult-raster
//!
//! The one exact software rasterizer every occult renderer draws through, the [`Frame`] it
//! draws into, depth queries on that frame, and color resolution ([`shade`]).
//!
//! ## Conventions (fixed here, once)
//! - **Screen space**: pixel `(x, y)` has its centre at `(x + 0.5, y + 0.5)`; `x` grows right,
//!   `y` grows **down** (row 0 is the top row). NDC `(-1, 1)` is the top-left corner.
//! - **Fixed point**: vertices snap to 1/256 pixel ([`SUBPIXEL_BITS`] = 8); edge functions are
//!   evaluated exactly in 64-bit integers.
//! - **Fill rule**: top-left. A pixel centre on an edge belongs to the triangle for which that
//!   edge is a left edge, or a top edge (horizontal, interior below). Two triangles sharing an
//!   edge therefore never both cover, nor both miss, a centre on it (watertight).
//! - **Depth**: reversed-Z `z_ndc = near / w` (see `occult-core`), greater is nearer, cleared
//!   to 0. Interpolated linearly in screen space and clamped to the triangle's own depth range
//!   (so a fragment is never nearer than its nearest vertex). Fragments farther than the far
//!   plane are discarded.
//! - **Visibility rule** (DESIGN invariant 1): a pixel keeps the fragment with the greatest
//!   depth, ties to the smaller item id ([`keep_fragment`]): frames do not depend on submission
//!   order, tile size or thread count.
//! - **Clipping**: homogeneous, against the near plane and a guard band of ±32768 pixels; both
//!   are computed from the inside vertex of each edge, so shared edges clip identically.
//! - **Faces**: counter-clockwise triangles (right-handed object space) are front faces; both
//!   faces are drawn unless [`RasterConfig::cull_backfaces`].
//!
//! ```
//! use occult_core::{Camera, Mesh, View, Vec3, glam::Affine3A};
//! use occult_raster::{Draw, DrawTriangles, Frame, RasterConfig, Rasterizer, RasterMode};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mesh = Mesh::new(vec![Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)], vec![[0, 1, 2]])?;
//! let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO), 64, 48)?;
//! let mut frame = Frame::new(64, 48)?;
//! let mut raster = Rasterizer::new(RasterConfig::default())?;
//! let draw = Draw { mesh: &mesh, triangles: DrawTriangles::All, clip_from_object: view.clip_from_object(&Affine3A::IDENTITY), first_item: 0 };
//! let counts = raster.draw(&view, &mut frame, &[draw], RasterMode::Full);
//! assert_eq!(counts.triangles_rasterized, 1);
//! assert!(frame.covered_pixel_count() > 100);
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

mod control;
mod frame;
pub mod nbuffer;
mod query;
mod raster;
mod shade;
pub mod zpyramid;

pub use control::FrameControl;
pub use frame::{keep_fragment, Frame, BLOCKED_DEPTH, CLEAR_DEPTH};
pub use nbuffer::{Extremum, NBuffer};
pub use query::{query_box, query_box_counted, query_rect, BoxQuery, PixelRect};
pub use raster::stencil::{StencilBuffer, StencilCounts, StencilDraw, StencilFaces};
pub use raster::{
    Draw, DrawTriangles, Meshlets, RasterConfig, RasterCounts, RasterMode, Rasterizer, Strategy, MAX_CLUSTER_VERTICES,
    SUBPIXEL_BITS,
};
pub use shade::{item_color, light_direction, shade, BACKGROUND};
pub use zpyramid::{PyramidCounts, PyramidTest, ZPyramid};

use thiserror::Error;

/// Errors of the raster layer.
#[derive(Debug, Error)]
pub enum RasterError {
    /// Zero or oversized resolution.
    #[error(transparent)]
    Resolution(#[from] occult_core::CoreError),
    /// The frame's buffers could not be allocated.
    #[error("cannot allocate {0} bytes of frame buffers")]
    OutOfMemory(usize),
    /// A bad configuration value; the message names it.
    #[error("bad raster configuration: {0}")]
    BadConfig(String),
}
