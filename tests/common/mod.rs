//! Shared helpers for integration tests: fixture paths and mesh checks.
#![allow(dead_code)]

use rbfsurf::geometry::TriMesh;
use std::path::PathBuf;

/// Path of a file under `data/`.
pub fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

/// Largest |signed distance| of the mesh vertices to an analytic surface.
pub fn max_vertex_error(mesh: &TriMesh, sdf: impl Fn(&[f64; 3]) -> f64) -> f64 {
    mesh.vertices
        .iter()
        .map(|v| sdf(v).abs())
        .fold(0.0, f64::max)
}
