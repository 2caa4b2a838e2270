//! Mesh post-processing: topology checks, GPU-friendly reordering and accuracy comparison.
//!
//! Everything here works on a plain [`crate::geometry::TriMesh`] and knows nothing of how it was made.
//! - [`topology`]: components, watertightness, manifoldness, orientation, Euler characteristic and genus.
//! - [`optimize`]: vertex-cache and vertex-fetch reordering with meshoptimizer.
//! - [`compare`]: Chamfer / Hausdorff distances to a reference mesh or point set.
//! - [`lod`]: error-bounded simplified levels of detail (meshoptimizer).
//! - [`trim`], [`peel`], [`border`], [`floaters`]: open-scan trimming, peeling the border back to
//!   the data without changing topology, manifold borders, floater removal by data support.

pub(crate) mod border;
pub(crate) mod color;
pub mod compare;
mod distance;
pub mod floaters;
pub(crate) mod fringes;
pub(crate) mod handles;
pub(crate) mod incidence;
pub(crate) mod lod;
pub mod optimize;
pub(crate) mod peel;
pub(crate) mod reach;
pub mod simplify;
#[cfg(test)]
pub(crate) mod test_meshes;
pub mod topology;
pub(crate) mod trim;

pub use color::{ColorMode, vertex_colors};
pub use compare::{CompareError, CompareParams, CompareReport, Reference, compare};
pub use optimize::{OptimizeError, OptimizeStats, optimize_for_gpu};
pub use topology::{MeshTopology, analyze, area, signed_volume};
