//! # occult-mpi
//!
//! occult beyond one process: sort-last rendering of any renderer, and the parallel local
//! z-buffer of Han & Zeiger's §IV, over MPI (feature `mpi`) or over thread ranks (the default:
//! the same code, ranks as threads of one process, so that the algorithms are tested with no
//! MPI installed). `docs/mpi.md` holds the design, the deviations from the paper and the
//! measured figures.
//!
//! | module | what |
//! | --- | --- |
//! | [`comm`] | the transport: [`Comm`], thread ranks, and the collectives built on send/receive |
//! | [`model`] | communication per frame and rank: measured at a few ranks, modelled for many |
//! | [`partition`] | the scene split among ranks, spatially and by cost, keeping item ids |
//! | [`composite`] | binary swap compositing by (depth, item id), then gather to rank 0 |
//! | [`plzb`] | Han & Zeiger §IV: the parallel local z-buffer (rays of the unfinished pixels shared, PVLs united) |
//! | [`sortlast`] | the renderer wrapper and the [`occult_render::RenderOptions`] hook that builds every renderer sort-last |
//!
//! ```
//! use std::sync::Arc;
//! use occult_core::{Camera, Mesh, Scene, View, Vec3};
//! use occult_raster::Frame;
//! use occult_render::{Algorithm, RenderOptions};
//! use occult_mpi::{run_threads, sort_last_options, SortLastConfig};
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).expect("a valid triangle");
//! let scene = Arc::new(Scene::from_mesh("tri", mesh).expect("a valid scene"));
//! let view = View::new(Camera::look_at(Vec3::new(0.3, 0.3, 2.0), Vec3::new(0.3, 0.3, 0.0)), 32, 32).expect("a valid view");
//! let frames = run_threads(2, |comm| {
//!     let options = sort_last_options(comm.clone(), RenderOptions::default(), SortLastConfig::default());
//!     let mut r = Algorithm::ZBUFFER.build(scene.clone(), &options).expect("zbuffer builds");
//!     let mut frame = Frame::new(32, 32).expect("a small frame");
//!     r.render(&view, &mut frame).expect("the frame renders");
//!     frame.covered_pixel_count()
//! });
//! assert!(*frames[0].as_ref().expect("rank 0 holds the frame") > 0);
//! ```
#![deny(missing_docs)]

pub mod comm;
pub mod composite;
pub mod model;
#[cfg(feature = "mpi")]
pub mod mpi_comm;
pub mod partition;
pub mod plzb;
pub mod sortlast;

pub use comm::{agree, broadcast, gather, run_threads, Comm, CommError, ThreadComm};
pub use plzb::ParallelLzb;
pub use sortlast::{sort_last_options, Fault, SortLast, SortLastConfig};
