//! The graph's steps as functions of the store: fit block `b`, polygonize region `r`, merge.
//! The local executor ([`super::reconstruct_tiled`]) and the distributed one (`crate::dist`) call
//! the same functions, so both give the same mesh; each step reads keyed values and writes one.

use super::prepare::Plan;
use super::store::{self, PointSet, SplineData, Store};
use super::tasks::{self, Quiet, block_key, piece_key, spline_key};
use crate::error::ReconError;
use crate::geometry::{Point3, TriMesh};
use crate::polygonize::PolygonizeStats;
use crate::progress::Progress;
use crate::report::{BlockReport, MatrixReport, PolygonizeReport, ResidualReport, Timings};
use std::collections::HashMap;
use std::time::Instant;

/// What fitting one block reports to the merge.
#[derive(Debug, Clone)]
pub(crate) struct BlockOutcome {
    /// The report's `blocks[]` entry.
    pub report: BlockReport,
    /// The block's system statistics.
    pub matrix: MatrixReport,
    /// Seconds of its assemble, order, factor and solve.
    pub timings: Timings,
}

/// What polygonizing one region (with points near it) reports to the merge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RegionOutcome {
    /// The polygonizer's counters.
    pub stats: PolygonizeStats,
    /// `Σ f(P)²` over the data points the region owns, normalised units².
    pub sum2: f64,
    /// `max |f(P)|` over them.
    pub max: f64,
    /// How many there are.
    pub count: usize,
}

/// Fit block `b`: read `points/{b}`, fit, write `spline/{b}`. `worker` names this process in
/// the report.
pub(crate) fn fit_step(
    plan: &Plan,
    store: &Store,
    b: usize,
    worker: &str,
    progress: &dyn Progress,
) -> Result<BlockOutcome, ReconError> {
    let t = Instant::now();
    let key = block_key(b);
    let set = PointSet::decode(&store.get(&key)?, &key)?;
    let fitted = tasks::fit_block(plan, b, &set, &Quiet(progress))?;
    drop(set);
    store.put(&spline_key(b), fitted.spline.encode())?;
    Ok(BlockOutcome {
        report: BlockReport {
            id: b,
            worker: worker.to_string(),
            points: fitted.points,
            seconds: t.elapsed().as_secs_f64(),
            peak_rss_mib: crate::report::peak_rss_mib(),
        },
        matrix: fitted.matrix,
        timings: fitted.timings,
    })
}

/// Polygonize region `r` and write `piece/{r}`; `None` when no point is near it (no piece).
pub(crate) fn region_step(
    plan: &Plan,
    store: &Store,
    r: usize,
    progress: &dyn Progress,
) -> Result<Option<RegionOutcome>, ReconError> {
    let set = region_points(plan, store, r)?;
    if set.points.is_empty() {
        return Ok(None);
    }
    let splines = region_splines(plan, store, r)?;
    let piece = tasks::polygonize_region(plan, r, &set, splines, &Quiet(progress))?;
    store.put(&piece_key(r), store::encode_piece(&piece.mesh))?;
    let (sum2, max, count) = piece.residual;
    Ok(Some(RegionOutcome {
        stats: piece.stats,
        sum2,
        max,
        count,
    }))
}

/// Weld the pieces of the regions in region order (`regions[r]` is region `r`'s outcome; its
/// piece is read and removed from the store). Returns the mesh, the statistics and the residual.
pub(crate) fn weld_step(
    plan: &Plan,
    store: &Store,
    regions: &[Option<RegionOutcome>],
) -> Result<(TriMesh, PolygonizeReport, ResidualReport), ReconError> {
    let mut poly = PolygonizeReport {
        cell_size: plan.grid.h,
        ..Default::default()
    };
    let (mut sum2, mut max, mut count) = (0.0, 0.0f64, 0usize);
    let mut mesh = TriMesh::default();
    let mut seen = HashMap::new();
    for (r, res) in regions.iter().enumerate() {
        let Some(o) = res else {
            continue;
        };
        poly.cells_total = o.stats.cells_total;
        poly.blocks_total = o.stats.blocks_total;
        poly.blocks_active += o.stats.blocks_active;
        poly.field_evaluations += o.stats.field_evaluations;
        sum2 += o.sum2;
        max = max.max(o.max);
        count += o.count;
        let key = piece_key(r);
        let piece = store::decode_piece(&store.get(&key)?, &key)?;
        store.remove(&key);
        super::merge::append_piece(&mut mesh, &mut seen, piece, r, &plan.grid.region_box(r));
    }
    poly.triangles_polygonized = mesh.triangles.len();
    let residual = ResidualReport {
        rms: (sum2 / count.max(1) as f64).sqrt(),
        max,
    };
    Ok((mesh, poly, residual))
}

/// The blocks' reports in block order, their systems summed, their solve timings added to
/// `timings`.
pub(crate) fn merge_blocks(
    outcomes: Vec<BlockOutcome>,
    timings: &mut Timings,
) -> (Vec<BlockReport>, MatrixReport) {
    let mut matrix = MatrixReport::default();
    let nb = outcomes.len();
    let mut reports = Vec::with_capacity(nb);
    for o in outcomes {
        super::super::blocks::merge_report(&mut matrix, o.matrix);
        timings.assemble += o.timings.assemble;
        timings.order += o.timings.order;
        timings.factor += o.timings.factor;
        timings.solve += o.timings.solve;
        reports.push(o.report);
    }
    matrix.blocks = nb;
    (reports, matrix)
}

/// Every point within the halo of region `r`'s box, in global order, from the point sets of the
/// blocks whose core meets that reach (every point lies in some block's core).
fn region_points(plan: &Plan, store: &Store, r: usize) -> Result<PointSet, ReconError> {
    let reach = plan.grid.region_box(r).inflated(plan.halo);
    let mut rows: Vec<(u32, Point3, Option<Point3>)> = Vec::new();
    for (b, block) in plan.blocks.iter().enumerate() {
        if !block.core.intersects(&reach) {
            continue;
        }
        let key = block_key(b);
        let set = PointSet::decode(&store.get(&key)?, &key)?;
        for (k, p) in set.points.iter().enumerate() {
            if reach.contains(p) {
                rows.push((set.ids[k], *p, set.normals.as_ref().map(|n| n[k])));
            }
        }
    }
    rows.sort_unstable_by_key(|r| r.0);
    rows.dedup_by_key(|r| r.0);
    let has_normals = rows.first().is_some_and(|r| r.2.is_some());
    Ok(PointSet {
        ids: rows.iter().map(|r| r.0).collect(),
        points: rows.iter().map(|r| r.1).collect(),
        normals: has_normals.then(|| rows.iter().map(|r| r.2.unwrap_or([0.0; 3])).collect()),
    })
}

/// The splines of the blocks whose outer box meets region `r`'s box, ascending block id.
fn region_splines(
    plan: &Plan,
    store: &Store,
    r: usize,
) -> Result<Vec<(usize, crate::rbf::Spline)>, ReconError> {
    let bx = plan.grid.region_box(r);
    let mut out = Vec::new();
    for (b, block) in plan.blocks.iter().enumerate() {
        if !block.outer.intersects(&bx) {
            continue;
        }
        let key = spline_key(b);
        let data = SplineData::decode(&store.get(&key)?, &key)?;
        if !data.levels.is_empty() {
            out.push((b, tasks::spline_from_data(data, &plan.params)?));
        }
    }
    Ok(out)
}
