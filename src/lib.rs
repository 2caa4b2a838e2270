//! # rbfsurf
//!
//! Watertight triangle meshes from point clouds with compactly supported radial basis functions
//! (Kojekine, Savchenko, Berzin & Hagiwara: carrier solid + Wendland CSRBF spline).
//!
//! Entry point: [`pipeline::reconstruct`] takes a [`geometry::PointCloud`] and [`params::ReconParams`]
//! and returns the mesh (input units) and a [`report::Report`]. Each stage is its own module:
//! [`geometry`] (types, cleaning, normalisation), [`spatial`] (octree, k-d tree), [`rbf`] (kernels,
//! carriers, assembly, field), [`ordering`], [`linalg`], [`polygonize`], [`mesh`], [`io`].
#![warn(missing_docs)]

pub mod clean;
#[cfg(feature = "cli")]
pub mod cli;
#[cfg(feature = "nats")]
pub mod dist;
pub mod error;
pub mod frep;
pub mod geometry;
pub mod io;
#[cfg(feature = "server")]
pub mod job;
pub mod linalg;
pub mod mesh;
pub mod normals;
pub mod ordering;
pub mod params;
pub mod pipeline;
pub mod polygonize;
pub mod progress;
pub mod rbf;
pub mod report;
#[cfg(feature = "server")]
pub mod server;
pub mod spatial;
pub mod variational;

pub use error::ReconError;
pub use params::ReconParams;
pub use pipeline::{Reconstruction, reconstruct};
