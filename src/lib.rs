//! # rbfsurf
//!
//! Watertight triangle meshes from point clouds with compactly supported radial basis functions
//! (Kojekine, Savchenko, Berzin & Hagiwara: carrier solid + Wendland CSRBF spline).
#![warn(missing_docs)]

pub mod geometry;
pub mod linalg;
pub mod polygonize;
pub mod progress;
pub mod variational;
