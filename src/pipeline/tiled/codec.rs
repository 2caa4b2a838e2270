//! Encodings of what crosses process boundaries in the distributed executor: the [`Plan`]
//! (decided once by prepare, read by every task) and the outcomes of the block and region steps
//! (read by the merge). A decoded plan gives the same mesh as the original, bit for bit: the
//! small parts are JSON (serde_json reads its floats back exactly), the subsample is binary, and
//! the local carrier's far field is rebuilt from the subsample as prepare built it.

use super::graph::{BlockOutcome, RegionOutcome};
use super::prepare::{BlockBox, CarrierPlan, Plan};
use super::store::PointSet;
use super::tasks::{CellRange, GridPlan};
use crate::clean::CleanStats;
use crate::error::StoreError;
use crate::geometry::{Aabb, Normalization, Point3};
use crate::params::{ReconParams, Smoothing};
use crate::polygonize::PolygonizeStats;
use crate::rbf::{CarrierKind, LocalFit, NoiseEstimate, SupportEstimate};
use crate::report::{BlockReport, LevelReport, MatrixReport, SolversUsed, Timings};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The plan's small parts.
#[derive(Serialize, Deserialize)]
struct PlanHeader {
    offset: Point3,
    scale: f64,
    support: SupportEstimate,
    noise: NoiseEstimate,
    lambda: f64,
    /// The local carrier's fit, resolved.
    local_fit: LocalFit,
    /// `[core.min, core.max, outer.min, outer.max]` and members per block.
    blocks: Vec<([Point3; 4], usize)>,
    halo: f64,
    carrier: CarrierHeader,
    grid_domain: [Point3; 2],
    resolution: usize,
    origin: Point3,
    h: f64,
    cells: [usize; 3],
    regions: Vec<[[usize; 3]; 2]>,
    clean: CleanStats,
    normals_flipped: bool,
    carrier_kind: CarrierKind,
}

#[derive(Serialize, Deserialize)]
enum CarrierHeader {
    Sphere {
        center: Point3,
        radius: f64,
    },
    Ellipsoid {
        center: Point3,
        axes: [Point3; 3],
        semi_axes: [f64; 3],
    },
    /// Rebuilt from the subsample and its normals; `far_field` false when prepare had none.
    Local {
        far_field: bool,
    },
}

fn corrupt(key: &str, what: &'static str) -> StoreError {
    StoreError::Corrupt {
        key: key.to_string(),
        what,
    }
}

impl Plan {
    /// `PLN1`, the header's length (u64 LE), the JSON header, the subsample as a point set.
    pub(crate) fn encode(&self) -> Vec<u8> {
        let carrier = match &self.carrier {
            CarrierPlan::Sphere { center, radius } => CarrierHeader::Sphere {
                center: *center,
                radius: *radius,
            },
            CarrierPlan::Ellipsoid {
                center,
                axes,
                semi_axes,
            } => CarrierHeader::Ellipsoid {
                center: *center,
                axes: *axes,
                semi_axes: *semi_axes,
            },
            CarrierPlan::Local { winding } => CarrierHeader::Local {
                far_field: winding.is_some(),
            },
        };
        let g = &self.grid;
        let header = PlanHeader {
            offset: self.normalization.offset,
            scale: self.normalization.scale,
            support: self.support,
            noise: self.noise,
            lambda: self.params.smoothing.lambda(),
            local_fit: self.params.carrier.fit,
            blocks: (self.blocks.iter())
                .map(|b| {
                    (
                        [b.core.min, b.core.max, b.outer.min, b.outer.max],
                        b.members,
                    )
                })
                .collect(),
            halo: self.halo,
            carrier,
            grid_domain: [g.domain.min, g.domain.max],
            resolution: g.resolution,
            origin: g.origin,
            h: g.h,
            cells: g.cells,
            regions: g.regions.iter().map(|r| [r.lo, r.hi]).collect(),
            clean: self.clean,
            normals_flipped: self.normals_flipped,
            carrier_kind: self.carrier_kind,
        };
        let json = serde_json::to_vec(&header).unwrap_or_default();
        let sample = PointSet {
            ids: (0..self.sample.len() as u32).collect(),
            points: self.sample.clone(),
            normals: self.sample_normals.clone(),
        };
        let mut out = b"PLN1".to_vec();
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        out.extend_from_slice(&sample.encode());
        out
    }

    /// Decodes [`Plan::encode`]; `params` are the job's parameters (the plan stores only the
    /// smoothing and the local fit it resolved).
    pub(crate) fn decode(
        bytes: &[u8],
        key: &str,
        params: &ReconParams,
    ) -> Result<Plan, StoreError> {
        if bytes.len() < 12 || &bytes[..4] != b"PLN1" {
            return Err(corrupt(key, "wrong tag"));
        }
        let len = u64::from_le_bytes(bytes[4..12].try_into().unwrap_or([0; 8])) as usize;
        let json = bytes
            .get(12..12usize.saturating_add(len))
            .ok_or_else(|| corrupt(key, "truncated"))?;
        let h: PlanHeader =
            serde_json::from_slice(json).map_err(|_| corrupt(key, "bad plan header"))?;
        let sample = PointSet::decode(&bytes[12 + len..], key)?;
        let carrier = match h.carrier {
            CarrierHeader::Sphere { center, radius } => CarrierPlan::Sphere { center, radius },
            CarrierHeader::Ellipsoid {
                center,
                axes,
                semi_axes,
            } => CarrierPlan::Ellipsoid {
                center,
                axes,
                semi_axes,
            },
            CarrierHeader::Local { far_field } => {
                let winding = match (far_field, &sample.normals) {
                    (false, _) => None,
                    (true, None) => return Err(corrupt(key, "far field without normals")),
                    (true, Some(n)) => {
                        rebuild_winding(&sample.points, n, h.normals_flipped, h.support.radius)
                    }
                };
                CarrierPlan::Local { winding }
            }
        };
        let aabb = |min: Point3, max: Point3| Aabb { min, max };
        Ok(Plan {
            normalization: Normalization {
                offset: h.offset,
                scale: h.scale,
            },
            support: h.support,
            noise: h.noise,
            params: ReconParams {
                smoothing: Smoothing::Lambda(h.lambda),
                carrier: crate::rbf::CarrierParams {
                    fit: h.local_fit,
                    ..params.carrier
                },
                ..params.clone()
            },
            blocks: (h.blocks.iter())
                .map(|(b, members)| BlockBox {
                    core: aabb(b[0], b[1]),
                    outer: aabb(b[2], b[3]),
                    members: *members,
                })
                .collect(),
            halo: h.halo,
            carrier,
            grid: GridPlan {
                domain: aabb(h.grid_domain[0], h.grid_domain[1]),
                resolution: h.resolution,
                origin: h.origin,
                h: h.h,
                cells: h.cells,
                regions: (h.regions.iter())
                    .map(|r| CellRange { lo: r[0], hi: r[1] })
                    .collect(),
            },
            sample: sample.points,
            sample_normals: sample.normals,
            clean: h.clean,
            normals_flipped: h.normals_flipped,
            carrier_kind: h.carrier_kind,
        })
    }
}

/// The far field as prepare built it: from the normals before any flip, then negated.
fn rebuild_winding(
    points: &[Point3],
    normals: &[Point3],
    flipped: bool,
    radius: f64,
) -> Option<Arc<crate::rbf::winding::WindingGrid>> {
    let before: Vec<Point3>;
    let sn = if flipped {
        before = normals.iter().map(|n| [-n[0], -n[1], -n[2]]).collect();
        &before
    } else {
        normals
    };
    let mut grid = crate::rbf::carrier::build_winding_grid(points, sn, radius)?;
    if flipped {
        grid.negate();
    }
    Some(Arc::new(grid))
}

/// A [`LevelReport`] with owned names.
#[derive(Serialize, Deserialize)]
struct LevelWire {
    n: usize,
    nnz: usize,
    support: f64,
    factor_values: usize,
    iterations: Option<usize>,
    solver: String,
    rhs_rms: f64,
}

/// A [`BlockOutcome`] with owned names.
#[derive(Serialize, Deserialize)]
struct BlockWire {
    report: BlockReport,
    n: usize,
    nnz: usize,
    bandwidth: usize,
    profile_values: usize,
    dense_values: usize,
    factor_values: usize,
    solvers: Vec<String>,
    levels: Vec<LevelWire>,
    timings: Timings,
}

/// The solver names a report can hold, as the static strings the report types keep.
fn solver_name(s: &str) -> &'static str {
    (crate::linalg::SolverKind::ALL.iter().map(|k| k.name()))
        .chain(["dense-lblt"])
        .find(|n| *n == s)
        .unwrap_or("unknown")
}

impl BlockOutcome {
    /// JSON.
    pub(crate) fn encode(&self) -> Vec<u8> {
        let m = &self.matrix;
        let wire = BlockWire {
            report: self.report.clone(),
            n: m.n,
            nnz: m.nnz,
            bandwidth: m.bandwidth,
            profile_values: m.profile_values,
            dense_values: m.dense_values,
            factor_values: m.factor_values,
            solvers: m
                .solver_used
                .names()
                .iter()
                .map(|s| s.to_string())
                .collect(),
            levels: (m.levels.iter())
                .map(|l| LevelWire {
                    n: l.n,
                    nnz: l.nnz,
                    support: l.support,
                    factor_values: l.factor_values,
                    iterations: l.iterations,
                    solver: l.solver.to_string(),
                    rhs_rms: l.rhs_rms,
                })
                .collect(),
            timings: self.timings,
        };
        serde_json::to_vec(&wire).unwrap_or_default()
    }

    /// Decodes [`BlockOutcome::encode`].
    pub(crate) fn decode(bytes: &[u8], key: &str) -> Result<BlockOutcome, StoreError> {
        let w: BlockWire =
            serde_json::from_slice(bytes).map_err(|_| corrupt(key, "bad block outcome"))?;
        let mut solver_used = SolversUsed::default();
        for s in &w.solvers {
            solver_used.add(solver_name(s));
        }
        Ok(BlockOutcome {
            report: w.report,
            matrix: MatrixReport {
                n: w.n,
                nnz: w.nnz,
                bandwidth: w.bandwidth,
                profile_values: w.profile_values,
                dense_values: w.dense_values,
                factor_values: w.factor_values,
                solver_used,
                levels: (w.levels.into_iter())
                    .map(|l| LevelReport {
                        n: l.n,
                        nnz: l.nnz,
                        support: l.support,
                        factor_values: l.factor_values,
                        iterations: l.iterations,
                        solver: solver_name(&l.solver),
                        rhs_rms: l.rhs_rms,
                    })
                    .collect(),
                blocks: 0,
            },
            timings: w.timings,
        })
    }
}

/// A region's outcome on the wire (`None`: no points near it).
#[derive(Serialize, Deserialize)]
struct RegionWire {
    cells_total: u64,
    blocks_total: usize,
    blocks_active: usize,
    field_evaluations: u64,
    sum2: f64,
    max: f64,
    count: usize,
}

/// JSON of a region step's result.
pub(crate) fn encode_region(o: &Option<RegionOutcome>) -> Vec<u8> {
    let wire = o.map(|o| RegionWire {
        cells_total: o.stats.cells_total,
        blocks_total: o.stats.blocks_total,
        blocks_active: o.stats.blocks_active,
        field_evaluations: o.stats.field_evaluations,
        sum2: o.sum2,
        max: o.max,
        count: o.count,
    });
    serde_json::to_vec(&wire).unwrap_or_default()
}

/// Decodes [`encode_region`].
pub(crate) fn decode_region(bytes: &[u8], key: &str) -> Result<Option<RegionOutcome>, StoreError> {
    let w: Option<RegionWire> =
        serde_json::from_slice(bytes).map_err(|_| corrupt(key, "bad region outcome"))?;
    Ok(w.map(|w| RegionOutcome {
        stats: PolygonizeStats {
            cells_total: w.cells_total,
            blocks_total: w.blocks_total,
            blocks_active: w.blocks_active,
            field_evaluations: w.field_evaluations,
        },
        sum2: w.sum2,
        max: w.max,
        count: w.count,
    }))
}
