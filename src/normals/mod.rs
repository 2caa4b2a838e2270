//! Normals for clouds that have none: PCA over the k nearest neighbours ([`estimate`]), then a
//! consistent orientation by propagation along a minimum spanning tree of the k-NN graph
//! ([`orient`], Hoppe, DeRose, Duchamp, McDonald & Stuetzle 1992).

mod estimate;
mod orient;

pub use estimate::estimate_normals;
pub use orient::orient_normals;

use crate::geometry::Point3;

/// Parameters of normal estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalParams {
    /// Neighbours for the PCA plane fit and the orientation graph (default 12; 8–30).
    pub neighbours: usize,
}

impl Default for NormalParams {
    fn default() -> Self {
        NormalParams { neighbours: 12 }
    }
}

/// Estimated, consistently oriented unit normals (outward for a closed surface sampled all round).
pub fn estimate_oriented_normals(points: &[Point3], params: &NormalParams) -> Vec<Point3> {
    let k = params.neighbours.clamp(3, points.len().max(3));
    let (normals, graph) = estimate_normals(points, k);
    orient_normals(points, normals, &graph)
}
