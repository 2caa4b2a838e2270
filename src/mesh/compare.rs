//! Accuracy of a mesh against a reference mesh or point set: symmetric Chamfer and Hausdorff distances.
//!
//! Both surfaces are sampled uniformly by area (seeded splitmix64, square-root barycentric mapping:
//! Osada et al., "Shape distributions", 2002, §4.2); each sample's distance to the *other* surface is the
//! exact point–triangle distance to its nearest triangle (Ericson's closest point, found with a BVH, see
//! `distance.rs`), or the nearest-point distance (kiddo k-d tree) when the reference is a point set,
//! whose samples are then its points. All distances are divided by the reference's bounding-box diagonal.
//! Cost `O((S + F) log F)` for `S` samples and `F` triangles, parallel over samples (rayon).

use crate::spatial::KdTree;
use rayon::prelude::*;
use serde::Serialize;
use thiserror::Error;

use super::distance::TriangleBvh;
use crate::geometry::{Aabb, Point3, TriMesh, add, cross, norm, scale, sub};

/// What a mesh is compared against.
#[derive(Debug, Clone, Copy)]
pub enum Reference<'a> {
    /// A reference surface (sampled by area; distances to it are point–triangle distances).
    Mesh(&'a TriMesh),
    /// A reference point set (every point is a sample; distances to it are nearest-point distances).
    Points(&'a [Point3]),
}

/// Sampling parameters of [`compare`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CompareParams {
    /// Samples drawn on each mesh surface (default 100 000; 10⁴–10⁶ is sensible).
    pub samples: usize,
    /// Seed of the sampler; the same seed gives the same report.
    pub seed: u64,
}

impl Default for CompareParams {
    fn default() -> Self {
        CompareParams {
            samples: 100_000,
            seed: 0x5EED_CAFE,
        }
    }
}

/// Distances between a mesh and its reference, all relative to the reference's bounding-box diagonal.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompareReport {
    /// `(mesh_to_ref_mean_rel + ref_to_mesh_mean_rel) / 2`.
    pub chamfer_rel: f64,
    /// `max(mesh_to_ref_max_rel, ref_to_mesh_max_rel)` (sampled two-sided Hausdorff distance).
    pub hausdorff_rel: f64,
    /// Mean distance from the mesh samples to the reference.
    pub mesh_to_ref_mean_rel: f64,
    /// Mean distance from the reference samples (or points) to the mesh.
    pub ref_to_mesh_mean_rel: f64,
    /// Point-set reference only: mean distance from the mesh samples to the plane fitted (PCA) to
    /// their [`PLANE_NEIGHBOURS`] nearest reference points, i.e. to the scan's local surface rather
    /// than to its nearest sample (whose distance never drops below about half the point spacing).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh_to_ref_plane_mean_rel: Option<f64>,
    /// Largest distance from a mesh sample to the reference.
    pub mesh_to_ref_max_rel: f64,
    /// Largest distance from a reference sample (or point) to the mesh.
    pub ref_to_mesh_max_rel: f64,
    /// Samples drawn on the mesh.
    pub samples: usize,
    /// Samples on the reference (its point count for a point-set reference).
    pub reference_samples: usize,
    /// The reference's bounding-box diagonal, in the units of the inputs (the divisor above).
    pub reference_diagonal: f64,
}

/// Why two surfaces could not be compared.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum CompareError {
    /// The mesh (or reference mesh) has no triangles / the point set has no points.
    #[error(
        "the {surface} is empty; give a mesh with at least one triangle or a non-empty point set"
    )]
    Empty {
        /// `"mesh"` or `"reference"`.
        surface: &'static str,
    },
    /// Every triangle has zero area, so the surface cannot be sampled.
    #[error("the {surface} has zero surface area (all triangles are degenerate)")]
    ZeroArea {
        /// `"mesh"` or `"reference"`.
        surface: &'static str,
    },
    /// A triangle refers to a missing vertex.
    #[error("triangle {triangle} of the {surface} refers to vertex {index}, which does not exist")]
    IndexOutOfRange {
        /// `"mesh"` or `"reference"`.
        surface: &'static str,
        /// Triangle number.
        triangle: usize,
        /// The offending index.
        index: u32,
    },
    /// A coordinate is NaN or infinite.
    #[error("vertex or point {index} of the {surface} has a non-finite coordinate")]
    NonFinite {
        /// `"mesh"` or `"reference"`.
        surface: &'static str,
        /// Vertex / point number.
        index: usize,
    },
    /// All reference points coincide, so there is no scale to normalise by.
    #[error("the reference has a zero bounding-box diagonal; give a reference with some extent")]
    DegenerateReference,
    /// `samples` was 0.
    #[error("the number of samples must be at least 1")]
    NoSamples,
}

/// Triangle corner positions of a validated mesh.
fn triangle_soup(mesh: &TriMesh, surface: &'static str) -> Result<Vec<[Point3; 3]>, CompareError> {
    if mesh.triangles.is_empty() {
        return Err(CompareError::Empty { surface });
    }
    if let Some(index) = mesh
        .vertices
        .iter()
        .position(|p| p.iter().any(|x| !x.is_finite()))
    {
        return Err(CompareError::NonFinite { surface, index });
    }
    mesh.triangles
        .iter()
        .enumerate()
        .map(|(triangle, t)| {
            let mut out = [[0.0; 3]; 3];
            for k in 0..3 {
                out[k] =
                    *mesh
                        .vertices
                        .get(t[k] as usize)
                        .ok_or(CompareError::IndexOutOfRange {
                            surface,
                            triangle,
                            index: t[k],
                        })?;
            }
            Ok(out)
        })
        .collect()
}

/// Uniform number in `[0, 1)` from a splitmix64 state.
fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// `n` points uniformly distributed by area on the triangles (sample `i` depends only on `seed` and `i`).
fn sample_by_area(
    tris: &[[Point3; 3]],
    n: usize,
    seed: u64,
    surface: &'static str,
) -> Result<Vec<Point3>, CompareError> {
    let mut cumulative = Vec::with_capacity(tris.len());
    let mut total = 0.0;
    for [a, b, c] in tris {
        total += 0.5 * norm(cross(sub(*b, *a), sub(*c, *a)));
        cumulative.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(CompareError::ZeroArea { surface });
    }
    Ok((0..n)
        .into_par_iter()
        .map(|i| {
            let mut state = seed ^ (i as u64).wrapping_mul(0xD1B5_4A32_D192_ED03);
            let target = splitmix(&mut state) * total;
            let k = cumulative
                .partition_point(|&c| c <= target)
                .min(tris.len() - 1);
            let [a, b, c] = tris[k];
            let s = splitmix(&mut state).sqrt();
            let r = splitmix(&mut state);
            add(
                scale(a, 1.0 - s),
                add(scale(b, s * (1.0 - r)), scale(c, s * r)),
            )
        })
        .collect())
}

/// Mean and maximum of the distances from `samples` to the surface measured by `dist`. Distances are
/// computed in parallel but summed in sample order, so the result does not depend on the thread schedule.
/// Reference points fitted by a plane in [`CompareReport::mesh_to_ref_plane_mean_rel`].
pub const PLANE_NEIGHBOURS: usize = 8;

/// Distance from `p` to the PCA plane of its [`PLANE_NEIGHBOURS`] nearest points in `tree`.
fn plane_distance(tree: &KdTree, points: &[Point3], p: Point3) -> f64 {
    use crate::spatial::SpatialIndex;
    let mut knn = Vec::with_capacity(PLANE_NEIGHBOURS);
    tree.nearest_k(&p, PLANE_NEIGHBOURS, &mut knn);
    let near: Vec<Point3> = knn.iter().map(|&(i, _)| points[i as usize]).collect();
    if near.len() < 3 {
        return knn.first().map_or(f64::INFINITY, |&(_, d)| d);
    }
    let fit = crate::geometry::pca::pca(&near);
    let n = fit.axes[2];
    crate::geometry::dot(sub(p, fit.centroid), n).abs()
}

fn mean_max(samples: &[Point3], dist: impl Fn(Point3) -> f64 + Sync) -> (f64, f64) {
    let d: Vec<f64> = samples.par_iter().map(|&p| dist(p)).collect();
    let sum: f64 = d.iter().sum();
    let max = d.iter().fold(0.0f64, |m, &v| m.max(v));
    (sum / samples.len().max(1) as f64, max)
}

/// Compares `mesh` with `reference` (see the module docs for the definitions).
///
/// # Example
/// ```
/// use rbfsurf::geometry::TriMesh;
/// use rbfsurf::mesh::{compare, CompareParams, Reference};
/// let tri = TriMesh {
///     vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///     normals: vec![],
///     triangles: vec![[0, 1, 2]],
///     colors: vec![],
/// };
/// let params = CompareParams { samples: 1000, ..Default::default() };
/// let r = compare(&tri, Reference::Mesh(&tri), &params).unwrap();
/// assert!(r.hausdorff_rel < 1e-12);
/// ```
pub fn compare(
    mesh: &TriMesh,
    reference: Reference,
    params: &CompareParams,
) -> Result<CompareReport, CompareError> {
    if params.samples == 0 {
        return Err(CompareError::NoSamples);
    }
    let mesh_tris = triangle_soup(mesh, "mesh")?;
    let mesh_samples = sample_by_area(&mesh_tris, params.samples, params.seed, "mesh")?;
    let ref_seed = params.seed ^ 0xA5A5_5A5A_F00D_BEEF;
    let mut plane_mean = None;
    let (diagonal, to_ref, ref_samples) = match reference {
        Reference::Mesh(r) => {
            let tris = triangle_soup(r, "reference")?;
            let diagonal = Aabb::from_points(tris.iter().flatten()).diagonal();
            let samples = sample_by_area(&tris, params.samples, ref_seed, "reference")?;
            let bvh = TriangleBvh::new(tris);
            let to_ref = mean_max(&mesh_samples, |p| bvh.nearest_dist2(p).sqrt());
            (diagonal, to_ref, samples)
        }
        Reference::Points(points) => {
            if points.is_empty() {
                return Err(CompareError::Empty {
                    surface: "reference",
                });
            }
            if let Some(index) = points.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
                return Err(CompareError::NonFinite {
                    surface: "reference",
                    index,
                });
            }
            let tree = KdTree::build(points).map_err(|_| CompareError::DegenerateReference)?;
            let nearest = |p: Point3| tree.nearest_one(&p).map_or(f64::INFINITY, |(_, d)| d);
            let to_ref = mean_max(&mesh_samples, nearest);
            plane_mean = Some(mean_max(&mesh_samples, |p| plane_distance(&tree, points, p)).0);
            (
                Aabb::from_points(points).diagonal(),
                to_ref,
                points.to_vec(),
            )
        }
    };
    if !(diagonal > 0.0 && diagonal.is_finite()) {
        return Err(CompareError::DegenerateReference);
    }
    let mesh_bvh = TriangleBvh::new(mesh_tris);
    let to_mesh = mean_max(&ref_samples, |p| mesh_bvh.nearest_dist2(p).sqrt());
    let rel = |x: f64| x / diagonal;
    Ok(CompareReport {
        chamfer_rel: rel(0.5 * (to_ref.0 + to_mesh.0)),
        hausdorff_rel: rel(to_ref.1.max(to_mesh.1)),
        mesh_to_ref_mean_rel: rel(to_ref.0),
        ref_to_mesh_mean_rel: rel(to_mesh.0),
        mesh_to_ref_plane_mean_rel: plane_mean.map(rel),
        mesh_to_ref_max_rel: rel(to_ref.1),
        ref_to_mesh_max_rel: rel(to_mesh.1),
        samples: mesh_samples.len(),
        reference_samples: ref_samples.len(),
        reference_diagonal: diagonal,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::{cube, torus};

    #[test]
    fn mesh_against_itself_is_zero() {
        let mesh = torus(2.0, 0.5, 32, 16);
        let params = CompareParams {
            samples: 20_000,
            seed: 3,
        };
        let r = compare(&mesh, Reference::Mesh(&mesh), &params).unwrap();
        assert!(r.hausdorff_rel <= 1e-12 && r.chamfer_rel <= 1e-12, "{r:?}");
        assert_eq!((r.samples, r.reference_samples), (20_000, 20_000));
        let again = compare(&mesh, Reference::Mesh(&mesh), &params).unwrap();
        assert_eq!(r, again);
        // Against its own vertices: every reference point lies on the mesh.
        let r = compare(&mesh, Reference::Points(&mesh.vertices), &params).unwrap();
        assert!(r.ref_to_mesh_max_rel <= 1e-12, "{r:?}");
        assert!(r.mesh_to_ref_mean_rel > 0.0);
    }

    #[test]
    fn plane_distance_sees_the_scan_surface_not_its_samples() {
        // A unit square and a 21×21 grid of points on it, then the same grid lifted by 0.01.
        let square = TriMesh {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![],
            colors: vec![],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let grid = |z: f64| -> Vec<Point3> {
            (0..21 * 21)
                .map(|i| [(i % 21) as f64 / 20.0, (i / 21) as f64 / 20.0, z])
                .collect()
        };
        let params = CompareParams {
            samples: 5000,
            seed: 1,
        };
        let on = compare(&square, Reference::Points(&grid(0.0)), &params).unwrap();
        let plane = on.mesh_to_ref_plane_mean_rel.unwrap();
        assert!(plane < 1e-12, "{plane}");
        // The nearest-sample distance is about a third of the spacing 0.05 (relative to √2).
        assert!(on.mesh_to_ref_mean_rel > 0.01, "{on:?}");
        let lifted = compare(&square, Reference::Points(&grid(0.01)), &params).unwrap();
        let d = lifted.mesh_to_ref_plane_mean_rel.unwrap() * lifted.reference_diagonal;
        assert!((d - 0.01).abs() < 1e-9, "{d}");
        let meshes = compare(&square, Reference::Mesh(&square), &params).unwrap();
        assert!(meshes.mesh_to_ref_plane_mean_rel.is_none());
    }

    #[test]
    fn scaled_cube_matches_analytic_distances() {
        let (half, delta) = (0.5, 0.005);
        let small = cube([-half; 3], 1.0);
        let big = cube([-(half + delta); 3], 1.0 + 2.0 * delta);
        let params = CompareParams {
            samples: 100_000,
            seed: 11,
        };
        let r = compare(&small, Reference::Mesh(&big), &params).unwrap();
        let diag = (1.0 + 2.0 * delta) * 3f64.sqrt();
        assert!((r.reference_diagonal - diag).abs() < 1e-12);
        // Every point of the small cube is exactly `delta` from the big one.
        assert!(
            (r.mesh_to_ref_mean_rel - delta / diag).abs() < 1e-12,
            "{r:?}"
        );
        assert!((r.mesh_to_ref_max_rel - delta / diag).abs() < 1e-12);
        // Big → small: sqrt(δ² + (|x|−½)₊² + (|y|−½)₊²) on each face; mean by quadrature over a quarter face.
        let m = 400;
        let step = delta / m as f64;
        let (mut strip, mut corner) = (0.0, 0.0);
        for i in 0..m {
            let u = (i as f64 + 0.5) * step;
            strip += (delta * delta + u * u).sqrt() * step;
            for j in 0..m {
                let v = (j as f64 + 0.5) * step;
                corner += (delta * delta + u * u + v * v).sqrt() * step * step;
            }
        }
        let quarter = half * half * delta + 2.0 * half * strip + corner;
        let mean = quarter / (half + delta).powi(2);
        assert!(
            (r.ref_to_mesh_mean_rel * diag - mean).abs() < 5e-4 * delta,
            "{r:?} vs {mean}"
        );
        let h = r.hausdorff_rel * diag;
        assert!(h > 1.39 * delta && h <= 3f64.sqrt() * delta + 1e-12, "{h}");
        assert!(
            (r.chamfer_rel - 0.5 * (r.mesh_to_ref_mean_rel + r.ref_to_mesh_mean_rel)).abs() < 1e-15
        );
    }

    #[test]
    fn invalid_inputs_are_errors() {
        let params = CompareParams::default();
        let c = cube([0.0; 3], 1.0);
        let empty = TriMesh::default();
        assert!(matches!(
            compare(&empty, Reference::Mesh(&c), &params),
            Err(CompareError::Empty { surface: "mesh" })
        ));
        assert!(matches!(
            compare(&c, Reference::Points(&[]), &params),
            Err(CompareError::Empty {
                surface: "reference"
            })
        ));
        assert!(matches!(
            compare(&c, Reference::Points(&[[1.0; 3], [1.0; 3]]), &params),
            Err(CompareError::DegenerateReference)
        ));
        let zero = CompareParams {
            samples: 0,
            seed: 0,
        };
        assert_eq!(
            compare(&c, Reference::Mesh(&c), &zero),
            Err(CompareError::NoSamples)
        );
        let mut flat = c.clone();
        flat.vertices.iter_mut().for_each(|p| *p = [0.0; 3]);
        assert!(matches!(
            compare(&flat, Reference::Mesh(&c), &params),
            Err(CompareError::ZeroArea { .. })
        ));
        let mut bad = c.clone();
        bad.triangles[2][0] = 42;
        assert!(matches!(
            compare(&c, Reference::Mesh(&bad), &params),
            Err(CompareError::IndexOutOfRange {
                triangle: 2,
                index: 42,
                ..
            })
        ));
    }
}
