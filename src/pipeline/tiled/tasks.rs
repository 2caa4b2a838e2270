//! The task functions of the graph: fit one block, polygonize one region. Pure functions of their
//! inputs (a point set, the plan, splines) returning encodable results, so any executor can run
//! them anywhere and a task run twice gives the same bytes.
//!
//! Seams weld exactly: a region's field is evaluated over its own points and the splines of the
//! blocks that reach it, and every neighbour query returns its hits in ascending id
//! ([`SortedIndex`]; a region's points are in global order), so every sum runs over the same terms
//! in the same order as in any other region or in one region holding everything. The value at a
//! grid corner, and the vertex on a grid edge, are then bit for bit the same on both sides of a
//! seam, and [`super::merge`] welds the pieces by position.

use super::prepare::{CarrierPlan, Plan};
use super::store::{LevelData, PointSet, SplineData};
use crate::error::ReconError;
use crate::geometry::{Aabb, Point3, TriMesh};
use crate::params::ReconParams;
use crate::polygonize::{PolygonizeParams, Region, Seeding, polygonize_in};
use crate::progress::Progress;
use crate::rbf::carrier::LocalCarrier;
use crate::rbf::{Carrier, Correction, PouBlock, RbfField, Spline, SplineLevel, plan_levels};
use crate::report::{MatrixReport, Timings};
use crate::spatial::{SpatialIndex, build_index};
use std::sync::Arc;

/// Store key of block `b`'s point set.
pub(crate) fn block_key(b: usize) -> String {
    format!("points/{b}")
}

/// Store key of block `b`'s spline.
pub(crate) fn spline_key(b: usize) -> String {
    format!("spline/{b}")
}

/// Store key of region `r`'s mesh piece.
pub(crate) fn piece_key(r: usize) -> String {
    format!("piece/{r}")
}

/// Cells per block of the polygonizer's grid (its `BLOCK`): regions are made of whole blocks so
/// that no block is shared by two regions.
const POLYGONIZER_BLOCK: usize = 16;

/// The polygonizer's grid over the domain (the same arithmetic as `polygonize::grid::Grid::new`,
/// which is private to it: cubic cells, `resolution` along the longest axis, centred) and its
/// split into regions of whole polygonizer blocks.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct GridPlan {
    /// The box handed to the polygonizer, normalised units.
    pub domain: Aabb,
    /// Cells along its longest axis.
    pub resolution: usize,
    /// Corner `(0, 0, 0)`.
    pub origin: Point3,
    /// Cell edge, normalised units.
    pub h: f64,
    /// Cells per axis.
    pub cells: [usize; 3],
    /// Cell ranges `[lo, hi)` of the regions.
    pub regions: Vec<CellRange>,
}

impl GridPlan {
    /// The domain of a closed surface (the points' box `bounds` and an analytic carrier's zero set, grown by
    /// one support radius plus three cells, as the in-memory pipeline does) and its regions of
    /// `region_cells` cells (rounded up to whole polygonizer blocks).
    pub(crate) fn from_bounds(
        bounds: Aabb,
        carrier: &CarrierPlan,
        radius: f64,
        resolution: usize,
        region_cells: usize,
    ) -> Result<GridPlan, ReconError> {
        let mut b = bounds;
        let analytic = match carrier {
            CarrierPlan::Sphere { center, radius } => Some(
                Aabb {
                    min: *center,
                    max: *center,
                }
                .inflated(*radius),
            ),
            CarrierPlan::Ellipsoid {
                center, semi_axes, ..
            } => Some(
                Aabb {
                    min: *center,
                    max: *center,
                }
                .inflated(semi_axes[0].max(semi_axes[1]).max(semi_axes[2])),
            ),
            CarrierPlan::Local { .. } => None,
        };
        if let Some(c) = analytic {
            b.grow(&c.min);
            b.grow(&c.max);
        }
        let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
        let domain = b.inflated(radius + 3.0 * longest / resolution as f64);
        let ext = domain.extent();
        let longest = ext.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if resolution == 0 || !(longest > 0.0 && longest.is_finite()) {
            return Err(crate::polygonize::PolygonizeError::EmptyDomain {
                min: domain.min,
                max: domain.max,
            }
            .into());
        }
        let h = longest / resolution as f64;
        let cells = ext.map(|e| ((e / h) * (1.0 - 1e-12)).ceil().max(1.0) as usize);
        let center = domain.center();
        let origin = [0, 1, 2].map(|k| center[k] - 0.5 * cells[k] as f64 * h);
        let step = region_cells.max(1).div_ceil(POLYGONIZER_BLOCK) * POLYGONIZER_BLOCK;
        let counts = cells.map(|c| c.div_ceil(step));
        let mut regions = Vec::new();
        for k in 0..counts[2] {
            for j in 0..counts[1] {
                for i in 0..counts[0] {
                    let lo = [i * step, j * step, k * step];
                    let hi = [0, 1, 2].map(|a| (lo[a] + step).min(cells[a]));
                    regions.push(CellRange { lo, hi });
                }
            }
        }
        Ok(GridPlan {
            domain,
            resolution,
            origin,
            h,
            cells,
            regions,
        })
    }

    /// The closed box of region `r`'s cells.
    pub(crate) fn region_box(&self, r: usize) -> Aabb {
        let c = &self.regions[r];
        Aabb {
            min: [0, 1, 2].map(|k| self.origin[k] + c.lo[k] as f64 * self.h),
            max: [0, 1, 2].map(|k| self.origin[k] + c.hi[k] as f64 * self.h),
        }
    }

    /// Whether `p` lies in region `r` (half-open in cells; each point of the grid is in one region).
    pub(crate) fn owns(&self, r: usize, p: &Point3) -> bool {
        let c = &self.regions[r];
        (0..3).all(|k| {
            let u = ((p[k] - self.origin[k]) / self.h).floor();
            let i = u.clamp(0.0, (self.cells[k] - 1) as f64) as usize;
            c.lo[k] <= i && i < c.hi[k]
        })
    }
}

/// A box of grid cells `[lo, hi)`: as a [`Region`] it keeps exactly the cells inside it, so the
/// regions of a [`GridPlan`] triangulate every cell once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct CellRange {
    pub lo: [usize; 3],
    pub hi: [usize; 3],
}

/// [`CellRange`] with the grid's geometry, for the polygonizer.
struct CellRegion<'a> {
    grid: &'a GridPlan,
    range: CellRange,
}

impl Region for CellRegion<'_> {
    /// A box (cell, tile or block, corners on the grid) touches the range when its corner-index
    /// interval overlaps `[lo, hi)` with a positive length on every axis (corner indices rounded,
    /// so the answer does not depend on the last bit of the box's coordinates).
    fn touches(&self, cell: &Aabb) -> bool {
        (0..3).all(|k| {
            let a = ((cell.min[k] - self.grid.origin[k]) / self.grid.h).round();
            let b = ((cell.max[k] - self.grid.origin[k]) / self.grid.h).round();
            a < self.range.hi[k] as f64 && b > self.range.lo[k] as f64
        })
    }
}

/// A spatial index whose radius queries return their hits in ascending index (the inner index
/// returns them in its own traversal order), so that sums over them do not depend on the tree.
pub(crate) struct SortedIndex(pub Box<dyn SpatialIndex + Send>);

impl SpatialIndex for SortedIndex {
    fn within(&self, q: &Point3, r: f64, out: &mut Vec<u32>) {
        self.0.within(q, r, out);
        out.sort_unstable();
    }
    fn nearest_k(&self, q: &Point3, k: usize, out: &mut Vec<(u32, f64)>) {
        self.0.nearest_k(q, k, out);
    }
    fn len(&self) -> usize {
        self.0.len()
    }
}

/// A [`SortedIndex`] over `points`.
fn sorted_index(
    points: &[Point3],
    params: &ReconParams,
) -> Result<Arc<dyn SpatialIndex + Send>, ReconError> {
    let inner = build_index(points, params.index, params.leaf_size)?;
    Ok(Arc::new(SortedIndex(inner)))
}

/// The carrier over `set` (the task's points with their halo): an analytic solid as planned, or
/// the local tangent planes of `set` with the shared far field. `index` is over `set.points`.
fn build_carrier(
    plan: &Plan,
    set: &PointSet,
    index: &Arc<dyn SpatialIndex + Send>,
) -> Result<Carrier, ReconError> {
    Ok(match &plan.carrier {
        CarrierPlan::Sphere { center, radius } => Carrier::Sphere {
            center: *center,
            radius: *radius,
        },
        CarrierPlan::Ellipsoid {
            center,
            axes,
            semi_axes,
        } => Carrier::Ellipsoid {
            center: *center,
            axes: *axes,
            semi_axes: *semi_axes,
        },
        CarrierPlan::Local { winding } => {
            let normals = set.normals.clone().ok_or(ReconError::NeedsNormals)?;
            let local = LocalCarrier::with_winding(
                set.points.clone(),
                normals,
                plan.support.radius,
                Arc::clone(index),
                winding.clone(),
                plan.params.carrier.fit,
            )
            .ok_or(ReconError::NeedsNormals)?;
            Carrier::Local(local)
        }
    })
}

/// Forwards cancellation only (a task's inner stages would move the outer progress bar).
pub(crate) struct Quiet<'a>(pub &'a dyn Progress);

impl Progress for Quiet<'_> {
    fn stage(&self, _stage: crate::progress::Stage) {}
    fn fraction(&self, _done: f64) {}
    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
}

/// What fitting one block produced.
pub(crate) struct FittedBlock {
    pub spline: SplineData,
    pub matrix: MatrixReport,
    pub timings: Timings,
    /// Points the block's system was fitted to.
    pub points: usize,
}

/// Fit block `b`: its members are the points of `set` inside its outer box; their carrier
/// offsets come from the carrier over all of `set`; the (single- or multi-level) spline is fitted
/// as in the in-memory block fit.
pub(crate) fn fit_block(
    plan: &Plan,
    b: usize,
    set: &PointSet,
    progress: &dyn Progress,
) -> Result<FittedBlock, ReconError> {
    let params = &plan.params;
    let outer = plan.blocks[b].outer;
    let index = sorted_index(&set.points, params)?;
    let carrier = build_carrier(plan, set, &index)?;
    super::super::check_cancel(progress)?;
    let members: Vec<usize> = (0..set.points.len())
        .filter(|&i| outer.contains(&set.points[i]))
        .collect();
    drop(index);
    let pts: Vec<Point3> = members.iter().map(|&i| set.points[i]).collect();
    let rhs: Vec<f64> = (super::super::csrbf::carrier_values(&carrier, &pts).iter())
        .map(|v| -v)
        .collect();
    drop(carrier);
    super::super::check_cancel(progress)?;
    let mut timings = Timings::default();
    if pts.is_empty() {
        return Ok(FittedBlock {
            spline: SplineData::default(),
            matrix: MatrixReport::default(),
            timings,
            points: 0,
        });
    }
    let index = sorted_index(&pts, params)?;
    let s = &plan.support;
    let levels = plan_levels(
        &pts,
        index.as_ref(),
        s.radius,
        s.mean_neighbours,
        params.levels,
    );
    let (spline, matrix) = super::super::csrbf::fit_levels(
        &pts,
        &index,
        &levels,
        rhs,
        params,
        progress,
        &mut timings,
    )?;
    Ok(FittedBlock {
        spline: SplineData {
            levels: (spline.levels.into_iter())
                .map(|l| LevelData {
                    centres: l.centres,
                    weights: l.weights,
                    support: l.support,
                })
                .collect(),
            polynomial: spline.polynomial,
        },
        matrix,
        timings,
        points: pts.len(),
    })
}

/// Rebuild a block's spline (each level's index a [`SortedIndex`]).
pub(crate) fn spline_from_data(
    data: SplineData,
    params: &ReconParams,
) -> Result<Spline, ReconError> {
    let mut levels = Vec::with_capacity(data.levels.len());
    for l in data.levels {
        let index = sorted_index(&l.centres, params)?;
        levels.push(SplineLevel {
            centres: l.centres,
            weights: l.weights,
            support: l.support,
            index,
        });
    }
    Ok(Spline {
        levels,
        polynomial: data.polynomial,
    })
}

/// What polygonizing one region produced.
pub(crate) struct RegionPiece {
    pub mesh: TriMesh,
    pub stats: crate::polygonize::PolygonizeStats,
    /// `Σ f(P)²`, `max |f(P)|` and the count over the data points the region owns.
    pub residual: (f64, f64, usize),
}

/// Polygonize region `r` of the grid: `set` holds every point within the halo of its box (global
/// order) and `splines` the blocks whose outer box meets it, as `(block id, spline)` in ascending
/// id. Also measures the field at the data points the region owns (the report's residual).
pub(crate) fn polygonize_region(
    plan: &Plan,
    r: usize,
    set: &PointSet,
    splines: Vec<(usize, Spline)>,
    progress: &dyn Progress,
) -> Result<RegionPiece, ReconError> {
    let params = &plan.params;
    let index = sorted_index(&set.points, params)?;
    let carrier = build_carrier(plan, set, &index)?;
    super::super::check_cancel(progress)?;
    let blocks = (splines.into_iter())
        .map(|(b, spline)| PouBlock {
            core: plan.blocks[b].core,
            outer: plan.blocks[b].outer,
            spline,
        })
        .collect();
    let field = RbfField {
        correction: Correction::Blocks(blocks),
        kernel: params.kernel,
        carrier,
        carrier_index: index,
        carrier_radius: plan.support.radius,
        finest_support: plan.support.radius,
        // Each region is polygonized alone and must meet its neighbours exactly at the border:
        // the far field is searched as everywhere else.
        unsupported_dropped: false,
    };
    let pp = PolygonizeParams {
        resolution: plan.grid.resolution,
        // A region's border cuts the surface anywhere: a piece of it that only clips the region
        // need not change sign at any probe inside, so every tile near the data is sampled (the
        // regions' meshes must meet exactly at their borders).
        seeding: Seeding::EveryTile,
        ..Default::default()
    };
    let region = CellRegion {
        grid: &plan.grid,
        range: plan.grid.regions[r],
    };
    let (mesh, stats) = polygonize_in(&field, &plan.grid.domain, &pp, &region, progress)?;
    super::super::check_cancel(progress)?;
    let owned: Vec<f64> = {
        use rayon::prelude::*;
        (set.points.par_iter())
            .filter(|p| plan.grid.owns(r, p))
            .map(|p| crate::polygonize::ScalarField::value(&field, p).abs())
            .collect()
    };
    let residual = (
        owned.iter().map(|v| v * v).sum(),
        owned.iter().fold(0.0f64, |m, &v| m.max(v)),
        owned.len(),
    );
    Ok(RegionPiece {
        mesh,
        stats,
        residual,
    })
}
