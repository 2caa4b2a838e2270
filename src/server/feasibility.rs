//! Feasibility of a job, checked at submit from the parsed upload (before anything is stored or
//! allocated for the reconstruction): the operator's limits, the memory the job would need, and
//! whether the requested support suits the cloud's spacing. Linear in the points (one pass over
//! the cloud for 64 probe points), so a refusal comes within seconds even at the point limit.
//! The estimates are deliberately simple; each refusal names the estimate and what to change.

use super::error::ApiError;
use crate::geometry::{Aabb, Normalization, Point3, PointCloud, dist2};
use crate::job::ServerConfig;
use crate::params::{Method, ReconParams, Support};
use axum::http::StatusCode;
use rayon::prelude::*;

/// Points probed for the spacing and neighbour estimates.
const PROBES: usize = 64;

/// Bytes per stored matrix entry of a CSRBF system with its factor (the pipeline's own estimate).
const BYTES_PER_NNZ: f64 = 32.0;

/// Largest dense variational system (the library's `TurkObrienParams::max_unknowns`).
const MAX_DENSE_UNKNOWNS: usize = 12_000;

/// Resolution the pipeline chooses at most when none is given.
const AUTO_RESOLUTION_MAX: usize = 200;

/// What the probes measured, normalised units (longest bbox edge 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CloudProbe {
    /// Median distance from a probe to its nearest distinct point.
    pub spacing: f64,
    /// Mean number of points within the requested support radius of a probe (itself included).
    pub neighbours: f64,
}

/// Estimated peak memory, MiB, of the mesh extracted at `resolution` cells along the longest axis:
/// about 12·res² triangles for a closed surface of area ~3 in the unit box, ~120 bytes each while
/// they are built and welded.
pub fn mesh_mib(resolution: usize) -> f64 {
    let r = resolution as f64;
    12.0 * r * r * 120.0 / (1u64 << 20) as f64
}

/// 422 `system_too_large` with the estimate.
fn too_large(message: String) -> ApiError {
    ApiError::new(
        StatusCode::UNPROCESSABLE_ENTITY,
        "system_too_large",
        message,
    )
}

/// Refuses a request that asks for more than the operator allows (only the resolution can be
/// asked above the server's limit; the memory budget is capped silently by the caller).
pub fn check_request(params: &ReconParams, cfg: &ServerConfig) -> Result<(), ApiError> {
    if let Some(r) = params.resolution
        && r > cfg.max_resolution
    {
        return Err(too_large(format!(
            "resolution {r} is above this server's limit of {} cells ({} grid cells asked, the mesh alone would need about {:.0} MiB); ask for resolution <= {} or omit it (the default adapts to the point spacing, at most {AUTO_RESOLUTION_MAX})",
            cfg.max_resolution,
            (r as u64).pow(3),
            mesh_mib(r),
            cfg.max_resolution
        )));
    }
    Ok(())
}

/// Refuses (4xx) a job that cannot fit its budget or whose support does not suit the cloud.
/// `params.max_memory_mib` is the job's budget (already capped by the server's).
pub fn check_cloud(cloud: &PointCloud, params: &ReconParams) -> Result<(), ApiError> {
    let n = cloud.points.len();
    let budget = params.max_memory_mib as f64;
    let resolution = params.resolution.unwrap_or(AUTO_RESOLUTION_MAX);
    let base = crate::pipeline::estimated_peak_mib(n as u64) + mesh_mib(resolution);
    if base > budget {
        return Err(too_large(format!(
            "{n} points at resolution {resolution} need about {base:.0} MiB (points, system and mesh), more than this job's memory budget of {budget:.0} MiB; subsample the cloud or lower the resolution"
        )));
    }
    if params.method == Method::Variational {
        // Pseudo-normal constraints: two per point plus the affine part.
        let unknowns = 2 * n + 4;
        let mib = (unknowns as f64).powi(2) * 8.0 / (1u64 << 20) as f64;
        if unknowns > MAX_DENSE_UNKNOWNS || mib > budget {
            return Err(too_large(format!(
                "method variational builds a dense system of about {unknowns} unknowns ({mib:.0} MiB) for {n} points; the limit is {MAX_DENSE_UNKNOWNS} unknowns within the budget of {budget:.0} MiB: use at most {} points or method csrbf",
                (MAX_DENSE_UNKNOWNS - 4) / 2
            )));
        }
        return Ok(());
    }
    if params.method != Method::Csrbf {
        return Ok(());
    }
    match params.support {
        Support::Radius(r) => {
            let probe = probe_cloud(&cloud.points, r);
            if probe.spacing > 0.0 && r < probe.spacing {
                return Err(ApiError::new(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    "unsuitable_parameter",
                    format!(
                        "support {r} is smaller than the point spacing (about {:.3e} normalised units): each point would see no neighbour and the surface would be the carrier alone; use support >= {:.3e} or neighbours=K (e.g. 30)",
                        probe.spacing,
                        3.0 * probe.spacing
                    ),
                ));
            }
            check_system(n, probe.neighbours, budget, &format!("support {r}"))
        }
        Support::Neighbours(k) => check_system(n, k as f64, budget, &format!("neighbours {k}")),
    }
}

fn check_system(n: usize, neighbours: f64, budget: f64, what: &str) -> Result<(), ApiError> {
    let nnz = n as f64 * neighbours.max(1.0);
    let mib = nnz * BYTES_PER_NNZ / (1u64 << 20) as f64;
    if mib > budget {
        return Err(too_large(format!(
            "{what} gives about {neighbours:.0} neighbours per point: a system of about {nnz:.3e} entries needing about {mib:.0} MiB for {n} points, more than this job's memory budget of {budget:.0} MiB; use a smaller support or fewer neighbours (the default, 30, adapts to the spacing)"
        )));
    }
    Ok(())
}

/// Spacing and neighbour count at radius `radius` (normalised units), measured exactly at
/// [`PROBES`] evenly strided probe points against every point: `O(PROBES · n)`, parallel.
pub fn probe_cloud(points: &[Point3], radius: f64) -> CloudProbe {
    let finite: Vec<Point3> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .copied()
        .collect();
    if finite.len() < 2 {
        return CloudProbe {
            spacing: 0.0,
            neighbours: finite.len() as f64,
        };
    }
    let norm = Normalization::from_aabb(&Aabb::from_points(&finite));
    let pts: Vec<Point3> = finite.iter().map(|p| norm.forward(p)).collect();
    let step = (pts.len() / PROBES).max(1);
    let probes: Vec<Point3> = pts.iter().step_by(step).take(PROBES).copied().collect();
    let r2 = radius * radius;
    let (nearest, counts) = pts
        .par_chunks(8192)
        .map(|chunk| {
            let mut nearest = vec![f64::INFINITY; probes.len()];
            let mut counts = vec![0u64; probes.len()];
            for p in chunk {
                for (k, q) in probes.iter().enumerate() {
                    let d = dist2(*p, *q);
                    if d > 0.0 && d < nearest[k] {
                        nearest[k] = d;
                    }
                    if d < r2 {
                        counts[k] += 1;
                    }
                }
            }
            (nearest, counts)
        })
        .reduce(
            || (vec![f64::INFINITY; probes.len()], vec![0; probes.len()]),
            |(mut n1, mut c1), (n2, c2)| {
                for k in 0..n1.len() {
                    n1[k] = n1[k].min(n2[k]);
                    c1[k] += c2[k];
                }
                (n1, c1)
            },
        );
    let mut d: Vec<f64> = nearest
        .into_iter()
        .filter(|v| v.is_finite())
        .map(f64::sqrt)
        .collect();
    d.sort_by(f64::total_cmp);
    CloudProbe {
        spacing: d.get(d.len() / 2).copied().unwrap_or(0.0),
        neighbours: counts.iter().sum::<u64>() as f64 / probes.len() as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probe_measures_a_regular_grid_exactly() {
        // 21 × 21 points spaced 0.05 on the unit square (z = 0): spacing 0.05, and a radius of
        // 0.051 holds the point and its 4 axis neighbours (fewer on the border).
        let pts: Vec<Point3> = (0..21 * 21)
            .map(|i| [(i % 21) as f64 * 0.05, (i / 21) as f64 * 0.05, 0.0])
            .collect();
        let p = probe_cloud(&pts, 0.051);
        assert!((p.spacing - 0.05).abs() < 1e-12, "{p:?}");
        assert!(p.neighbours > 3.5 && p.neighbours <= 5.0, "{p:?}");
    }

    #[test]
    fn tiny_and_huge_supports_are_refused_with_4xx() {
        let cloud = crate::geometry::synthetic::Shape::by_name("sphere")
            .unwrap()
            .sample(5000, 1);
        let mut p = ReconParams {
            support: Support::Radius(1e-300),
            ..Default::default()
        };
        let e = check_cloud(&cloud, &p).unwrap_err();
        assert_eq!(
            (e.status.as_u16(), e.body.code.as_str()),
            (422, "unsuitable_parameter")
        );
        p.support = Support::Radius(1.0);
        p.max_memory_mib = 64;
        let e = check_cloud(&cloud, &p).unwrap_err();
        assert_eq!(
            (e.status.as_u16(), e.body.code.as_str()),
            (422, "system_too_large")
        );
        assert!(e.body.message.contains("MiB"), "{}", e.body.message);
        p.support = Support::Radius(0.1);
        p.max_memory_mib = 8192;
        check_cloud(&cloud, &p).unwrap();
    }
}
