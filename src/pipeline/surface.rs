//! From the fitted field to the kept surface (normalised units): decide open or closed, polygonize
//! (only the band the data support when open), trim, make the border manifold, drop floaters and
//! small pieces.
//!
//! The rule for open or closed (`--boundary auto`, local carrier): data all around an object (a
//! closed object with holes from occlusion, e.g. under its base) give a closed surface, the holes
//! closed by the carrier; a single-view range scan or an open scene give an open surface on the
//! data. Data that surround their middle (every cone of directions wider than
//! [`SURROUNDED_BELOW_DEG`] from the centroid or the box centre holds a point, [`surround_cone`])
//! are closed: whatever surface lies away from them is holes in data taken all around (oceans on a
//! globe, a sparse scan's gaps), which the carrier closes. So are data whose oriented points
//! enclose a volume (their winding number reaches ¾ over at least [`ENCLOSED_ABOVE`] of where it is
//! clearly non-zero, [`encloses_volume`]: a closed object whose thin limbs or a hole through its
//! body leave its middle open, e.g. an elk). Otherwise it is decided on a coarse
//! polygonization (a quarter of the resolution, ~1/16 of the triangles) without its floaters: when
//! more than [`AUTO_TRIM_FRACTION`] of its area is farther than the support radius from every
//! point, the carrier continues the data's own sheet far beyond them (an open scan) and the
//! surface is trimmed; a closed object's unsupported patches are a tiny part (bunny 10k: 0.03%),
//! and the carrier's blobs away from the data are floaters, not counted. A coarse surface that is
//! not closed inside the domain (a sheet of the carrier runs out to the box) counts as open too:
//! trimming removes that sheet, closing would keep it; so does a final surface that is not closed
//! inside the domain (a sheet too thin for the coarse pass, or one beside data that surround
//! their middle): it is trimmed like an open scan.
//!
//! Open surfaces are polygonized only in the band the data support ([`DataBand`]: cells whose
//! centre is within the support radius plus half a cell diagonal of a point), then the triangles
//! whose centroid is farther than the support radius from every point are dropped, except pinholes
//! enclosed by kept surface ([`trim::keep_enclosed_holes`]: a data gap wider than the band stays a
//! hole, a gap barely wider than the trim radius leaves no one-triangle hole), and bow-tie vertices
//! are removed ([`crate::mesh::border`]): one manifold sheet per connected scan piece, one boundary
//! loop per border or hole. Every surface then loses its floaters (components carried by fewer than
//! `min_support` of the points, [`crate::mesh::floaters`]) and, with `--min-component`, its small
//! pieces; an open one then has its border peeled back to `border_reach` support radii from the
//! data wherever that keeps the pieces, holes and handles ([`crate::mesh::peel`]: the trim radius
//! bridges the gaps between returns, the peel removes the overhang beyond the last ones); every
//! surface is then simplified to the chord-error tolerance ([`crate::mesh::simplify`], topology
//! kept). A closed surface then loses its small handles ([`crate::mesh::handles`]): bridges and
//! pinholes whose shortest loop around is at most `max_handle_loop` support radii, where two parts
//! came closer than the data separate them.

use super::FittedField;
use crate::error::ReconError;
use crate::geometry::{Aabb, Point3, TriMesh, surround_cone};
use crate::mesh::simplify;
use crate::mesh::{area, floaters, handles, trim};
use crate::params::{Boundary, ChordTolerance, ReconParams};
use crate::polygonize::{
    DataBand, Everywhere, PolygonizeParams, Region, ScalarField, polygonize_in,
};
use crate::progress::{Progress, Stage};
use crate::rbf::CarrierKind;
use crate::report::PolygonizeReport;
use rayon::prelude::*;

/// Share of unsupported surface area above which `--boundary auto` trims: an open scan's
/// extrapolated sheet is a large part of the surface; a closed scan's sparse patches are a tiny one.
const AUTO_TRIM_FRACTION: f64 = 0.02;

/// Widest empty cone (half-angle, degrees) below which the data count as taken all around the
/// object ([`surround_cone`]): its unsupported surface is then holes to close, however much of it
/// there is (measured: closed objects ≤ 17°, open scans and scenes ≥ 34°).
const SURROUNDED_BELOW_DEG: f64 = 25.0;

/// Enclosed share ([`encloses_volume`]) from which data count as enclosing a volume (measured:
/// closed objects 0.28–0.87, among them an elk at 3k points 0.28 and a trefoil knot 0.6; open
/// scans, scenes and one-sided sheets 0–0.03).
const ENCLOSED_ABOVE: f64 = 0.15;

/// The coarse decision pass uses the resolution divided by this (at least [`COARSE_MIN`] cells).
const COARSE_DIVISOR: usize = 4;

/// Fewest cells along the longest axis of the coarse decision pass.
const COARSE_MIN: usize = 16;

/// Polygonize `fit.field` on `domain` at `resolution` and post-process it (see the module doc).
/// Returns the mesh, whether it was trimmed open, and the report's `polygonize` section.
pub(crate) fn extract_surface(
    fit: &FittedField,
    params: &ReconParams,
    domain: &Aabb,
    resolution: usize,
    progress: &dyn Progress,
) -> Result<(TriMesh, bool, PolygonizeReport), ReconError> {
    let longest = domain.extent().iter().fold(0.0f64, |a, &b| a.max(b));
    let mut s = PolygonizeReport {
        cell_size: longest / resolution as f64,
        ..Default::default()
    };
    let open = match params.boundary {
        Boundary::Closed => false,
        Boundary::Trim => true,
        Boundary::Auto if fit.carrier != Some(CarrierKind::Local) => false,
        // Data all around are closed without the coarse pass (a surface that still leaves the
        // domain is trimmed below), and so are data that enclose a volume.
        Boundary::Auto if surrounded(fit, &mut s) => false,
        Boundary::Auto if encloses_volume(fit, &mut s) => false,
        Boundary::Auto => {
            let share = unsupported_share(fit, params, domain, resolution, progress)?;
            s.unsupported_share = Some(share);
            share > AUTO_TRIM_FRACTION
        }
    };
    let pp = PolygonizeParams {
        resolution,
        ..Default::default()
    };
    if open && let Some(switch) = &fit.far_field {
        // An open scan: the tangent planes continue its sheet, which the band and the trim cut.
        switch.store(false, std::sync::atomic::Ordering::Relaxed);
    }
    let band;
    let region: &dyn Region = if open {
        band = DataBand::new(&fit.points, fit.support_radius)?;
        &band
    } else {
        &Everywhere
    };
    let t = std::time::Instant::now();
    let (mut mesh, stats) = polygonize_in(fit.field.as_ref(), domain, &pp, region, progress)?;
    s.extract_s = t.elapsed().as_secs_f64();
    s.cells_total = stats.cells_total;
    s.blocks_total = stats.blocks_total;
    s.blocks_active = stats.blocks_active;
    s.field_evaluations = stats.field_evaluations;
    s.triangles_polygonized = mesh.triangles.len();
    // Auto decided closed, but the surface leaves the domain (a thin sheet of the carrier the coarse
    // pass missed): trim it like an open scan rather than keep a sheet out to the box.
    let open = open
        || (params.boundary == Boundary::Auto
            && fit.carrier == Some(CarrierKind::Local)
            && crate::mesh::topology::has_boundary_edge(&mesh.triangles));
    if open {
        let mut drop = trim::unsupported_triangles(&mesh, &fit.points, fit.support_radius);
        trim::keep_enclosed_holes(&mesh, &mut drop);
        s.trimmed_triangles = trim::remove_triangles(&mut mesh, &drop);
        s.border_triangles = crate::mesh::border::make_manifold(&mut mesh);
    }
    let (drop, n) = floaters::floaters(&mesh, &fit.points, fit.support_radius, params.min_support);
    s.floaters_removed = n;
    s.floater_triangles = trim::remove_triangles(&mut mesh, &drop);
    let (drop, n) = trim::small_components(&mesh, params.min_component);
    s.small_components_removed = n;
    s.small_component_triangles = trim::remove_triangles(&mut mesh, &drop);
    if open {
        // After the floaters: they are judged on the trimmed surface, whose vertices the points
        // count for.
        let reach = params.border_reach * fit.support_radius;
        s.peeled_triangles =
            crate::mesh::peel::peel_border(&mut mesh, &fit.points, reach, fit.support_radius);
        if params.min_support > 0.0 {
            let (drop, n) = crate::mesh::fringes::fringes(&mesh, &fit.points, fit.support_radius);
            s.fringes_removed = n;
            s.fringe_triangles = trim::remove_triangles(&mut mesh, &drop);
        }
    }
    let t = std::time::Instant::now();
    simplify_to_chord_error(fit, params, &mut mesh, &mut s);
    s.simplify_s = t.elapsed().as_secs_f64();
    if !open {
        cut_small_handles(&mut mesh, params, fit.support_radius, &mut s);
    }
    Ok((mesh, open, s))
}

/// Cuts the closed `mesh`'s handles whose shortest loop is at most `params.max_handle_loop`
/// support radii (`support_radius`, the mesh's units; nothing when the parameter is 0) and records
/// them in the report: the last step on a closed surface, in memory and out of core alike.
pub(crate) fn cut_small_handles(
    mesh: &mut TriMesh,
    params: &ReconParams,
    support_radius: f64,
    s: &mut PolygonizeReport,
) {
    if params.max_handle_loop <= 0.0 {
        return;
    }
    let t = std::time::Instant::now();
    let h = handles::remove_small_handles(mesh, params.max_handle_loop * support_radius);
    s.handles_removed = h.removed;
    s.handles_kept = h.kept;
    s.handle_loop_max = (h.loop_lengths.iter()).fold(0.0, |m, l| m.max(l / support_radius));
    s.handles_s = t.elapsed().as_secs_f64();
}

/// Whether the data surround the object (the surface is then closed, and the coarse pass not
/// run); records the widest empty cone in the report.
fn surrounded(fit: &FittedField, s: &mut PolygonizeReport) -> bool {
    let cone = surround_cone(&fit.points).to_degrees();
    s.empty_cone_deg = Some(cone);
    cone < SURROUNDED_BELOW_DEG
}

/// Whether the oriented data enclose a volume
/// ([`crate::rbf::carrier::LocalCarrier::enclosed_share`] at least [`ENCLOSED_ABOVE`]), recorded
/// in the report: a closed object whose middle the data do not surround (thin limbs, a hole
/// through the body) is still closed, while an open scan, a scene or a one-sided sheet never
/// reaches it.
fn encloses_volume(fit: &FittedField, s: &mut PolygonizeReport) -> bool {
    let share = match fit.rbf.as_deref().map(|f| &f.carrier) {
        Some(crate::rbf::Carrier::Local(l)) => l.enclosed_share(),
        _ => None,
    };
    s.enclosed_share = share;
    share.is_some_and(|e| e >= ENCLOSED_ABOVE)
}

/// Centroids sampled for the measured chord error (every k-th triangle beyond this many).
const CHORD_SAMPLES: usize = 20_000;

/// Simplifies `mesh` (normalised units) to `params.chord_error` and records the tolerance, the
/// triangle counts and the chord error measured on the result: `|f| / |∇f|` (the first-order
/// distance to the zero set) at the centroids of the triangles (every k-th, at most
/// [`CHORD_SAMPLES`]); the grid mesh's own vertices lie on the zero set, its chords do not.
fn simplify_to_chord_error(
    fit: &FittedField,
    params: &ReconParams,
    mesh: &mut TriMesh,
    s: &mut PolygonizeReport,
) {
    s.triangles_before_simplify = mesh.triangles.len();
    if let ChordTolerance::Spacing(x) = params.chord_error
        && fit.support.spacing.is_finite()
        && fit.support.spacing > 0.0
    {
        let tol = x * fit.support.spacing;
        let stats = simplify::simplify_to_tolerance(mesh, tol);
        s.chord_tolerance = Some(tol);
        s.simplify_error = stats.error;
    }
    let step = mesh.triangles.len().div_ceil(CHORD_SAMPLES).max(1);
    let centroids: Vec<Point3> = (mesh.triangles.iter().step_by(step))
        .map(|t| crate::mesh::reach::centroid(mesh, t))
        .collect();
    let d = first_order_distances(fit.field.as_ref(), &centroids, CHORD_BUCKET * s.cell_size);
    s.chord_error_max = d.iter().fold(0.0, |a: f64, &b| a.max(b));
    s.chord_error_mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
}

/// Edge of the boxes the chord samples are evaluated in together, in grid cells (a few tiles: the
/// field gathers its candidates once per box).
const CHORD_BUCKET: f64 = 8.0;

/// `|f| / |∇f|` (`|f|` where the gradient vanishes) at each of `points`, evaluated box by box:
/// the points are bucketed into cubes of edge `edge` and each cube's are evaluated through one
/// [`crate::polygonize::ScalarField::prepare`] (the values of per-point evaluation, gathered once
/// per cube). Parallel over the cubes; the result is in the order of `points`.
fn first_order_distances(field: &dyn ScalarField, points: &[Point3], edge: f64) -> Vec<f64> {
    let edge = if edge.is_finite() && edge > 0.0 {
        edge
    } else {
        1.0
    };
    let key = |p: &Point3| p.map(|v| (v / edge).floor() as i64);
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_unstable_by_key(|&i| key(&points[i as usize]));
    let buckets: Vec<&[u32]> = order
        .chunk_by(|a, b| key(&points[*a as usize]) == key(&points[*b as usize]))
        .collect();
    let per_bucket: Vec<Vec<(u32, f64)>> = buckets
        .par_iter()
        .map(|ids| {
            let pts: Vec<Point3> = ids.iter().map(|&i| points[i as usize]).collect();
            let region = Aabb::from_points(&pts);
            let mut prepared = field.prepare(&region);
            let (mut f, mut g) = (vec![0.0; pts.len()], vec![[0.0; 3]; pts.len()]);
            prepared.values(&pts, &mut f);
            prepared.gradients(&pts, &mut g);
            (ids.iter().zip(f.iter().zip(&g)))
                .map(|(&i, (f, g))| {
                    let (f, g) = (f.abs(), crate::geometry::norm(*g));
                    (i, if g > 0.0 { f / g } else { f })
                })
                .collect()
        })
        .collect();
    let mut out = vec![0.0; points.len()];
    for (i, d) in per_bucket.into_iter().flatten() {
        out[i as usize] = d;
    }
    out
}

/// Share of the surface area farther than the support radius from every data point, measured on
/// a coarse polygonization of the whole domain (normalised units) without its floaters (pieces of
/// the carrier away from the data, which the final surface drops anyway): what is left unsupported
/// is the carrier continuing the data's own sheet, i.e. an open scan. 1 when that surface is not
/// closed inside the domain (a sheet of the carrier runs out to the box: only trimming removes it).
fn unsupported_share(
    fit: &FittedField,
    params: &ReconParams,
    domain: &Aabb,
    resolution: usize,
    progress: &dyn Progress,
) -> Result<f64, ReconError> {
    let cells = (resolution / COARSE_DIVISOR).max(COARSE_MIN);
    let pp = PolygonizeParams {
        resolution: cells,
        refine_steps: 0,
        ..Default::default()
    };
    let quiet = CancelOnly(progress);
    let (mut mesh, _) = polygonize_in(fit.field.as_ref(), domain, &pp, &Everywhere, &quiet)?;
    let longest = domain.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    let reach = fit.support_radius + 3f64.sqrt() * longest / cells as f64;
    let (drop, _) = floaters::floaters(&mesh, &fit.points, reach, params.min_support);
    trim::remove_triangles(&mut mesh, &drop);
    if crate::mesh::topology::has_boundary_edge(&mesh.triangles) {
        // The carrier's surface leaves the domain: closing it would keep a sheet out to the box.
        return Ok(1.0);
    }
    let total = area(&mesh);
    let drop = trim::unsupported_triangles(&mesh, &fit.points, fit.support_radius);
    trim::remove_triangles(&mut mesh, &drop);
    let supported = area(&mesh);
    Ok(if total > 0.0 {
        ((total - supported) / total).max(0.0)
    } else {
        0.0
    })
}

/// Forwards only cancellation (the coarse pass does not move the progress bar).
struct CancelOnly<'a>(&'a dyn Progress);

impl Progress for CancelOnly<'_> {
    fn stage(&self, _stage: Stage) {}
    fn fraction(&self, _done: f64) {}
    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
}
