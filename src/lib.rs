//! # rbfsurf
//!
//! Watertight triangle meshes from point clouds with compactly supported radial basis functions
//! (Kojekine, Savchenko, Berzin & Hagiwara: carrier solid + Wendland CSRBF spline).
//!
//! ## Two entry points
//!
//! - [`reconstruct`]`(&cloud, &params, &progress)`: a [`PointCloud`] in memory to a
//!   [`Reconstruction`] (the [`TriMesh`] in the input's units and its [`Report`]). The whole
//!   cloud is reconstructed in memory; a cloud whose estimate exceeds
//!   [`ReconParams::max_memory_mib`] is refused with [`ReconError::TooManyPoints`] before any
//!   work. Write the mesh with [`write_mesh`].
//! - [`run`]`(source, &params, &limits, &output, &progress)`: a point file (or its bytes) to a
//!   mesh file and a JSON report, what the command line and the HTTP service call. It reads the
//!   point count first and, when the cloud would not fit the memory budget, streams it through
//!   the out-of-core task graph instead ([`pipeline::plan_execution`]); its outputs are written
//!   atomically.
//!
//! Both take [`ReconParams`] (every default in [`ReconParams::default`]) and a [`Progress`]
//! ([`NoProgress`] when nobody listens; a `cancelled()` answer stops the work with
//! [`ReconError::Cancelled`]).
//!
//! ## Example: points in memory to a GLB file
//!
//! ```
//! use rbfsurf::{MeshFormat, NoProgress, PointCloud, ReconParams};
//!
//! // 2,000 points with outward normals on a sphere of radius 2 (a Fibonacci lattice).
//! let n = 2000;
//! let turn = std::f64::consts::PI * (3.0 - 5f64.sqrt());
//! let normals: Vec<[f64; 3]> = (0..n)
//!     .map(|i| {
//!         let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
//!         let r = (1.0 - z * z).sqrt();
//!         let a = turn * i as f64;
//!         [r * a.cos(), r * a.sin(), z]
//!     })
//!     .collect();
//! let cloud = PointCloud {
//!     points: normals.iter().map(|v| v.map(|c| 2.0 * c)).collect(),
//!     normals: Some(normals),
//!     ..Default::default()
//! };
//!
//! // The default parameters on a coarse grid (32 cells along the longest edge).
//! let params = ReconParams { resolution: Some(32), ..Default::default() };
//! let result = rbfsurf::reconstruct(&cloud, &params, &NoProgress)?;
//! let mesh = &result.mesh;
//! let topology = rbfsurf::mesh::analyze(mesh);
//! assert!(topology.watertight && topology.genus == Some(0));
//! for v in &mesh.vertices {
//!     let r = v.iter().map(|c| c * c).sum::<f64>().sqrt();
//!     assert!((r - 2.0).abs() < 0.05, "a vertex at radius {r}");
//! }
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("sphere.glb");
//! rbfsurf::write_mesh(&path, mesh, MeshFormat::Glb(Default::default()))?;
//! let back = rbfsurf::read_mesh(&path)?;
//! assert_eq!(back.triangles.len(), mesh.triangles.len());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Example: a point file to a mesh file
//!
//! ```
//! use rbfsurf::{MeshFormat, NoProgress, PointSource, ReadLimits, ReconParams, RunOutput};
//! use std::path::Path;
//!
//! let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/kitten.ply");
//! let dir = tempfile::tempdir()?;
//! let mesh = dir.path().join("kitten.glb");
//! let report = dir.path().join("kitten.json");
//! let output = RunOutput {
//!     mesh: &mesh,
//!     format: MeshFormat::from_path(&mesh)?,
//!     report: Some(&report),
//!     field: None,
//!     job_memory_mib: None,
//! };
//! let params = ReconParams { resolution: Some(48), ..Default::default() };
//! let summary = rbfsurf::run(
//!     PointSource::File(&input),
//!     &params,
//!     &ReadLimits::default(),
//!     &output,
//!     &NoProgress,
//! )?;
//! assert!(summary.triangles > 1000 && mesh.exists() && report.exists());
//! // The kitten's tail makes a handle.
//! assert_eq!(summary.report.mesh.genus, Some(1));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Modules
//!
//! Each stage is its own module: [`geometry`] (types, synthetic shapes), [`spatial`] (octree,
//! k-d tree), [`normals`], [`rbf`] (kernels, carriers, assembly, field), [`ordering`],
//! [`linalg`], [`polygonize`], [`mesh`] (topology, comparison, post-processing), [`io`] (point
//! and mesh formats), [`pipeline`] (the stages in order, the out-of-core task graph), [`frep`]
//! (volume modelling over fitted fields), [`variational`] (the global fits and the 2-D
//! workbench). With the default features also `server` (the HTTP service), `job` (its job
//! model) and `dist` (the distributed executor on NATS).
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

pub use error::{ErrorKind, ReconError};
pub use geometry::{Point3, PointCloud, TriMesh};
pub use io::{GlbOptions, MeshFormat, ReadLimits, read_mesh, read_point_cloud, write_mesh};
pub use params::ReconParams;
pub use pipeline::{
    PointSource, Reconstruction, RunError, RunOutput, RunSummary, reconstruct, run,
};
pub use progress::{NoProgress, Progress};
pub use report::Report;
