//! Carrier solids `g` (the seed's `f_c`, sign flipped so that `g < 0` inside, `g > 0` outside):
//! every data point gets the offset `r_i = −g(P_i)`, the CSRBF spline `U` interpolates the offsets and
//! the surface is `f = g + U = 0`. Away from every centre `U = 0`, so the carrier alone decides the sign.
//!
//! - `sphere`: least-squares algebraic sphere (Kåsa fit: minimise Σ(|P|² − 2c·P − d)², a 4×4 linear
//!   system), radius then set to the RMS distance to the centre; falls back to the bounding sphere when
//!   the fit is degenerate. `g = |x − c| − ρ` (a signed distance, 1-Lipschitz).
//! - `ellipsoid`: PCA fit: centre = centroid, axes = principal directions, semi-axes `a_k = √(3 λ_k)`
//!   (exact for a uniformly sampled ellipsoid surface). `g = a_min (|M(x − c)| − 1)`, 1-Lipschitz.
//! - `local`: a partition of unity of the tangent planes of the k nearest oriented points
//!   (Hoppe et al. 1992 signed distance made continuous; Ohtake et al. 2003 use local quadrics the
//!   same way). Needs normals; its zero set follows the data, so offsets are small and ears, handles
//!   and concavities keep the right sign. Farther than the support radius from every point its sign
//!   comes from the generalized winding number of the oriented points ([`super::winding`]): `½ − w`,
//!   blended in between `R` and `2R`, so the carrier has no zero far from the data except where `w`
//!   crosses ½, i.e. across the holes of a closed object's sampling.

use super::Kernel;
use super::winding::WindingGrid;
use crate::geometry::{Aabb, Point3, dist2, dot, norm, normalized, pca::pca, sub};
use crate::spatial::{KdTree, SpatialIndex};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

mod near;
mod quadric;
pub use near::NearPoints;
pub use quadric::{LocalFit, Quadric};

/// Which carrier solid to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CarrierKind {
    /// `local` when the points carry normals, else `ellipsoid`.
    #[default]
    Auto,
    /// The seed's sphere (least-squares fit).
    Sphere,
    /// PCA ellipsoid.
    Ellipsoid,
    /// Partition of unity of local tangent planes (needs normals).
    Local,
}

impl CarrierKind {
    /// Command-line / report name.
    pub fn name(self) -> &'static str {
        match self {
            CarrierKind::Auto => "auto",
            CarrierKind::Sphere => "sphere",
            CarrierKind::Ellipsoid => "ellipsoid",
            CarrierKind::Local => "local",
        }
    }
}

impl std::fmt::Display for CarrierKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for CarrierKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [Self::Auto, Self::Sphere, Self::Ellipsoid, Self::Local]
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("unknown carrier '{s}' (use auto, sphere, ellipsoid or local)"))
    }
}

/// Errors of carrier fitting.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CarrierError {
    /// `local` asked for but the input has no usable normals.
    #[error(
        "the local carrier needs oriented normals and the input has none: use --carrier ellipsoid or sphere"
    )]
    NeedsNormals,
    /// The ellipsoid degenerates (points on a plane or line).
    #[error(
        "the points are (nearly) flat: the PCA ellipsoid is degenerate (semi-axes {semi_axes:?}); give normals and use --carrier local"
    )]
    Degenerate {
        /// The fitted semi-axes, normalised units.
        semi_axes: [f64; 3],
    },
}

/// A fitted carrier solid in normalised units.
#[derive(Debug)]
pub enum Carrier {
    /// `g = |x − center| − radius`.
    Sphere {
        /// Centre.
        center: Point3,
        /// Radius, normalised units.
        radius: f64,
    },
    /// `g = a_min (|M(x − center)| − 1)` with `M = diag(1/a) · axesᵀ`.
    Ellipsoid {
        /// Centre.
        center: Point3,
        /// Unit principal directions.
        axes: [Point3; 3],
        /// Semi-axis lengths along `axes`, normalised units.
        semi_axes: [f64; 3],
    },
    /// Partition of unity of tangent planes.
    Local(LocalCarrier),
}

impl Carrier {
    /// The fitted kind (never [`CarrierKind::Auto`]).
    pub fn kind(&self) -> CarrierKind {
        match self {
            Carrier::Sphere { .. } => CarrierKind::Sphere,
            Carrier::Ellipsoid { .. } => CarrierKind::Ellipsoid,
            Carrier::Local(_) => CarrierKind::Local,
        }
    }

    /// Report name of the fitted kind.
    pub fn name(&self) -> &'static str {
        match self {
            Carrier::Sphere { .. } => "sphere",
            Carrier::Ellipsoid { .. } => "ellipsoid",
            Carrier::Local(_) => "local",
        }
    }

    /// `g(x)`: negative inside, positive outside, about a signed distance (normalised units).
    pub fn value(&self, x: &Point3) -> f64 {
        match self {
            Carrier::Sphere { center, radius } => norm(sub(*x, *center)) - radius,
            Carrier::Ellipsoid {
                center,
                axes,
                semi_axes,
            } => {
                let (q, _) = ellipsoid_local(x, center, axes, semi_axes);
                min3(semi_axes) * (norm(q) - 1.0)
            }
            Carrier::Local(l) => l.value(x),
        }
    }

    /// `∇g(x)` (zero where undefined, e.g. at a sphere's centre).
    pub fn gradient(&self, x: &Point3) -> Point3 {
        match self {
            Carrier::Sphere { center, .. } => normalized(sub(*x, *center)).unwrap_or([0.0; 3]),
            Carrier::Ellipsoid {
                center,
                axes,
                semi_axes,
            } => {
                let (q, _) = ellipsoid_local(x, center, axes, semi_axes);
                let nq = norm(q);
                if nq == 0.0 {
                    return [0.0; 3];
                }
                let s = min3(semi_axes) / nq;
                let mut g = [0.0; 3];
                for k in 0..3 {
                    let c = s * q[k] / semi_axes[k];
                    for d in 0..3 {
                        g[d] += c * axes[k][d];
                    }
                }
                g
            }
            Carrier::Local(l) => l.value_gradient(x).1,
        }
    }

    /// A bound on `|∇g|` when one is known (sphere and ellipsoid: 1).
    pub fn lipschitz(&self) -> Option<f64> {
        match self {
            Carrier::Local(_) => None,
            _ => Some(1.0),
        }
    }

    /// Bounding box of the carrier's zero set when it is a closed analytic solid.
    pub fn zero_set_bounds(&self) -> Option<Aabb> {
        match self {
            Carrier::Sphere { center, radius } => Some(
                Aabb {
                    min: *center,
                    max: *center,
                }
                .inflated(*radius),
            ),
            Carrier::Ellipsoid {
                center, semi_axes, ..
            } => {
                let a = semi_axes[0].max(semi_axes[1]).max(semi_axes[2]);
                Some(
                    Aabb {
                        min: *center,
                        max: *center,
                    }
                    .inflated(a),
                )
            }
            Carrier::Local(_) => None,
        }
    }
}

fn min3(a: &[f64; 3]) -> f64 {
    a[0].min(a[1]).min(a[2])
}

fn ellipsoid_local(
    x: &Point3,
    c: &Point3,
    axes: &[Point3; 3],
    semi: &[f64; 3],
) -> (Point3, Point3) {
    let d = sub(*x, *c);
    let u = [dot(d, axes[0]), dot(d, axes[1]), dot(d, axes[2])];
    ([u[0] / semi[0], u[1] / semi[1], u[2] / semi[2]], u)
}

/// Distance from the data, in support radii, where the far field starts to take over.
const FAR_FROM: f64 = 0.5;
/// Distance from the data, in support radii, where the winding number starts to overrule planes
/// that disagree with it (see [`LocalCarrier`]'s far field), and the width of that hand-over.
const GUARD_FROM: f64 = 0.25;
// The far field is evaluated from `GUARD_FROM` on, which must cover `FAR_FROM` too.
const _: () = assert!(GUARD_FROM < FAR_FROM);
const GUARD_WIDTH: f64 = 0.5;
/// `|1 − 2w|` below which the guard is off and above which it is fully on (`w` within 0.2 /
/// 0.05 of 0 or 1).
const GUARD_DECIDED: (f64, f64) = (0.6, 0.9);
/// Disagreement `−g (1 − 2w)` (normalised units, in support radii) at which the guard is fully on.
const GUARD_SCALE: f64 = 0.125;

/// Weight of the far field by distance from the data, `s((d₁ − R/2)/R)`, and its derivative in
/// `(d₁ − R/2)/R` (see [`LocalCarrier`]'s far field).
fn far_ramp(d1: f64, radius: f64) -> (f64, f64) {
    smoothstep((d1 - FAR_FROM * radius) / radius)
}

/// Confidence of the winding number `c(a)`, `a = 1 − 2w`: 0 for `|a| ≤ 0.2`, 1 for `|a| ≥ 0.6`;
/// and its derivative in `(|a| − 0.2)/0.4`.
fn far_confidence(a: f64) -> (f64, f64) {
    smoothstep((a.abs() - 0.2) / 0.4)
}

/// The C¹ smoothstep `3u² − 2u³` of `u` clamped to [0, 1], and its derivative.
fn smoothstep(u: f64) -> (f64, f64) {
    let v = u.clamp(0.0, 1.0);
    let d = if u > 0.0 && u < 1.0 {
        6.0 * v * (1.0 - v)
    } else {
        0.0
    };
    (v * v * (3.0 - 2.0 * v), d)
}

/// Fewest points the local carrier blends at any `x` (the far field's vote, see [`LocalCarrier`]).
pub const FAR_NEIGHBOURS: usize = 16;

/// Parameters of carrier fitting.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CarrierParams {
    /// Which solid.
    pub kind: CarrierKind,
    /// How the local carrier fits each point's term (`Auto` is taken as `Quadric` here; the
    /// pipelines resolve it from the noise estimate first, see [`LocalFit::resolve`]).
    pub fit: LocalFit,
}

/// Fit the carrier to normalised `points` (with unit `normals` when known). The local carrier blends
/// planes within `radius` (normalised units) found with `index` (over `points`).
pub fn fit_carrier(
    points: &[Point3],
    normals: Option<&[Point3]>,
    params: &CarrierParams,
    radius: f64,
    index: &Arc<dyn SpatialIndex + Send>,
) -> Result<Carrier, CarrierError> {
    let kind = match params.kind {
        CarrierKind::Auto if normals.is_some() => CarrierKind::Local,
        CarrierKind::Auto => CarrierKind::Ellipsoid,
        k => k,
    };
    match kind {
        CarrierKind::Sphere => Ok(fit_sphere(points)),
        CarrierKind::Ellipsoid => fit_ellipsoid(points),
        _ => {
            let normals = normals.ok_or(CarrierError::NeedsNormals)?;
            LocalCarrier::new(points, normals, radius, Arc::clone(index), params.fit)
                .map(Carrier::Local)
                .ok_or(CarrierError::NeedsNormals)
        }
    }
}

/// Neighbours per point for its area (`π d_k² / k`).
const AREA_NEIGHBOURS: usize = 8;

/// The winding grid of `points` with unit `normals` (zero = unusable), as a [`LocalCarrier`]
/// builds it over its own points (see [`winding_grid`]). An out-of-core reconstruction builds it
/// once from a bounded subsample of the whole cloud (the areas then come from the subsample's
/// own spacing, so the dipoles still cover the surface) and shares it with every block's carrier
/// through [`LocalCarrier::with_winding`]. `None` when no normal is usable.
pub fn build_winding_grid(
    points: &[Point3],
    normals: &[Point3],
    radius: f64,
) -> Option<WindingGrid> {
    let (valid_ids, valid_tree) = usable_points(points, normals)?;
    winding_grid(points, normals, &valid_tree, &valid_ids, radius).map(|b| *b)
}

/// The ids of the points with a usable (non-zero) normal and a k-d tree over them (item `k` of
/// the tree is point `ids[k]`). `None` when no normal is usable or the lengths differ.
fn usable_points(points: &[Point3], normals: &[Point3]) -> Option<(Vec<u32>, KdTree)> {
    if normals.len() != points.len() {
        return None;
    }
    let valid_ids: Vec<u32> = (0..points.len() as u32)
        .filter(|&i| normals[i as usize] != [0.0; 3])
        .collect();
    if valid_ids.is_empty() {
        return None;
    }
    let valid_points: Vec<Point3> = valid_ids.iter().map(|&i| points[i as usize]).collect();
    Some((valid_ids, KdTree::build(&valid_points).ok()?))
}

/// The winding grid of the points with usable normals: areas from their [`AREA_NEIGHBOURS`]
/// nearest neighbours, cells of about `radius` over the points' box grown by `2 radius` and two
/// cells (beyond it the far field is clamped to the boundary's, about `w = 0`).
fn winding_grid(
    points: &[Point3],
    normals: &[Point3],
    valid_tree: &KdTree,
    valid_ids: &[u32],
    radius: f64,
) -> Option<Box<WindingGrid>> {
    use rayon::prelude::*;
    let vp: Vec<Point3> = valid_ids.iter().map(|&i| points[i as usize]).collect();
    let vn: Vec<Point3> = valid_ids.iter().map(|&i| normals[i as usize]).collect();
    let areas: Vec<f64> = vp
        .par_iter()
        .map_init(Vec::new, |knn, p| {
            valid_tree.nearest_k(p, AREA_NEIGHBOURS + 1, knn);
            let m = knn.len().saturating_sub(1).max(1);
            let d = knn.last().map_or(0.0, |&(_, d)| d);
            std::f64::consts::PI * d * d / m as f64
        })
        .collect();
    let bbox = Aabb::from_points(&vp);
    let longest = bbox.extent().iter().fold(0.0f64, |a, &b| a.max(b));
    let cell = (0.5 * radius).max(longest / super::winding::MAX_CELLS as f64);
    let domain = bbox.inflated(2.0 * radius + 2.0 * cell);
    WindingGrid::build(&vp, &vn, &areas, &domain, cell).map(Box::new)
}

/// Least-squares (Kåsa) sphere; bounding sphere when the fit is degenerate.
pub fn fit_sphere(points: &[Point3]) -> Carrier {
    let bbox = Aabb::from_points(points);
    let fallback = Carrier::Sphere {
        center: bbox.center(),
        radius: 0.5 * bbox.diagonal(),
    };
    // Normal equations of  2 c·P + d = |P|²  in unknowns (c, d), centred for conditioning.
    let o = bbox.center();
    let mut m = [[0.0f64; 5]; 4];
    for p in points {
        let q = sub(*p, o);
        let row = [2.0 * q[0], 2.0 * q[1], 2.0 * q[2], 1.0];
        let rhs = dot(q, q);
        for a in 0..4 {
            for b in 0..4 {
                m[a][b] += row[a] * row[b];
            }
            m[a][4] += row[a] * rhs;
        }
    }
    let Some(sol) = gauss4(m) else {
        return fallback;
    };
    let center = [sol[0] + o[0], sol[1] + o[1], sol[2] + o[2]];
    let ms: f64 = points
        .iter()
        .map(|p| dot(sub(*p, center), sub(*p, center)))
        .sum::<f64>();
    let radius = (ms / points.len() as f64).sqrt();
    if !radius.is_finite() || radius <= 0.0 || norm(sub(center, o)) > 10.0 * bbox.diagonal() {
        return fallback;
    }
    Carrier::Sphere { center, radius }
}

/// Solve a 4×4 system given as an augmented matrix; `None` when (nearly) singular.
#[allow(clippy::needless_range_loop)] // Gauss–Jordan on a fixed-size matrix
fn gauss4(mut m: [[f64; 5]; 4]) -> Option<[f64; 4]> {
    let scale = (0..4).map(|i| m[i][i].abs()).fold(0.0, f64::max);
    for col in 0..4 {
        let piv = (col..4).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[piv][col].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(col, piv);
        for r in 0..4 {
            if r != col {
                let f = m[r][col] / m[col][col];
                for c in col..5 {
                    m[r][c] -= f * m[col][c];
                }
            }
        }
    }
    Some([
        m[0][4] / m[0][0],
        m[1][4] / m[1][1],
        m[2][4] / m[2][2],
        m[3][4] / m[3][3],
    ])
}

/// PCA ellipsoid.
pub fn fit_ellipsoid(points: &[Point3]) -> Result<Carrier, CarrierError> {
    let p = pca(points);
    let semi_axes = p.variances.map(|v| (3.0 * v.max(0.0)).sqrt());
    if semi_axes[2] <= 1e-6 * semi_axes[0].max(f64::MIN_POSITIVE) {
        return Err(CarrierError::Degenerate { semi_axes });
    }
    Ok(Carrier::Ellipsoid {
        center: p.centroid,
        axes: p.axes,
        semi_axes,
    })
}

/// Partition of unity of the tangent planes of the oriented points within the radius
/// `ρ(x) = max(R, d_K(x))` (`R` the support radius, `d_K(x)` the distance from `x` to its
/// [`FAR_NEIGHBOURS`]-th nearest point with a usable normal):
/// `g(x) = Σ w_j n_j·(x − p_j) / Σ w_j` with `w_j = ψ(|x − p_j| / ρ(x))` (ψ = Wendland C²).
/// Near the data `ρ = R`, so sharing `R` with the spline lets one neighbour query serve both sums.
/// Where fewer than K points lie within `R` (sparse parts, off the data) the weights widen to the K
/// nearest points; `ρ` is continuous (at the switch `d_K = R`, and the K-th point has weight 0), so
/// `g` is. Earlier versions used the single nearest point's plane there (Hoppe et al. 1992): one
/// badly estimated normal on a thin part (the bunny's ears: PCA normals 87° off) then made a
/// negative pocket in its Voronoi cell, a closed blob off the surface. K planes outvote it.
pub struct LocalCarrier {
    points: Vec<Point3>,
    /// Unit normals; zero where the input normal was unusable (such points get no weight).
    normals: Vec<Point3>,
    /// Each point's curvature correction of its plane ([`quadric`]); empty with planes.
    quadrics: Vec<Quadric>,
    /// `Plane`, `Quadric` or `WideQuadric` (never `Auto`).
    fit: LocalFit,
    radius: f64,
    index: Arc<dyn SpatialIndex + Send>,
    valid_tree: KdTree,
    valid_ids: Vec<u32>,
    /// The winding number of the oriented points (the far field's sign); shared when given by
    /// [`LocalCarrier::with_winding`].
    winding: Option<Arc<WindingGrid>>,
    /// Whether the far field is used (see [`LocalCarrier::far_field_switch`]).
    far_field: Arc<AtomicBool>,
}

impl std::fmt::Debug for LocalCarrier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalCarrier")
            .field("points", &self.points.len())
            .field("radius", &self.radius)
            .finish()
    }
}

impl LocalCarrier {
    /// Build from points, normals (same length, zero or non-finite = unusable), the support radius,
    /// an index over `points` and the fit of each point's term (`Auto` = `Quadric`). `None` when
    /// no normal is usable.
    pub fn new(
        points: &[Point3],
        normals: &[Point3],
        radius: f64,
        index: Arc<dyn SpatialIndex + Send>,
        fit: LocalFit,
    ) -> Option<Self> {
        let normals: Vec<Point3> = normals
            .iter()
            .map(|n| normalized(*n).unwrap_or([0.0; 3]))
            .collect();
        Self::from_parts(points.to_vec(), normals, radius, index, fit)
    }

    /// Rebuild from saved parts: the points, their unit normals exactly as [`Self::normals`] gave
    /// them (not renormalised, so a loaded carrier evaluates bit for bit like the saved one), the
    /// radius, an index over `points` and the fit. `None` when no normal is usable or the lengths
    /// differ. The quadrics are fitted again from these parts; flipping the normals negates them
    /// exactly, so a carrier saved after [`Self::flip_normals`] loads bit for bit.
    pub fn from_parts(
        points: Vec<Point3>,
        normals: Vec<Point3>,
        radius: f64,
        index: Arc<dyn SpatialIndex + Send>,
        fit: LocalFit,
    ) -> Option<Self> {
        let (valid_ids, valid_tree) = usable_points(&points, &normals)?;
        let winding =
            winding_grid(&points, &normals, &valid_tree, &valid_ids, radius).map(Arc::from);
        Some(Self::assemble(
            points,
            normals,
            radius,
            index,
            (valid_ids, valid_tree),
            winding,
            fit,
        ))
    }

    /// A carrier over `points` (a part of a larger cloud, e.g. one block with its halo) whose far
    /// field is `winding`, built once for the whole cloud ([`build_winding_grid`]), instead of
    /// one of its own points. `normals` are unit vectors as [`Self::normals`] gives them (zero =
    /// unusable), already oriented: [`Self::flip_normals`] leaves a shared grid unchanged, so
    /// orient the normals and negate the grid before sharing them. `None` when no normal is
    /// usable or the lengths differ.
    pub fn with_winding(
        points: Vec<Point3>,
        normals: Vec<Point3>,
        radius: f64,
        index: Arc<dyn SpatialIndex + Send>,
        winding: Option<Arc<WindingGrid>>,
        fit: LocalFit,
    ) -> Option<Self> {
        let usable = usable_points(&points, &normals)?;
        Some(Self::assemble(
            points, normals, radius, index, usable, winding, fit,
        ))
    }

    fn assemble(
        points: Vec<Point3>,
        normals: Vec<Point3>,
        radius: f64,
        index: Arc<dyn SpatialIndex + Send>,
        (valid_ids, valid_tree): (Vec<u32>, KdTree),
        winding: Option<Arc<WindingGrid>>,
        fit: LocalFit,
    ) -> Self {
        // `Auto` without a noise estimate is the clean-data choice.
        let fit = fit.resolve(false);
        let quadrics = match fit.fit_scale() {
            None => Vec::new(),
            Some(scale) => quadric::fit_quadrics(&points, &normals, scale * radius, index.as_ref()),
        };
        LocalCarrier {
            points,
            normals,
            quadrics,
            fit,
            radius,
            index,
            valid_tree,
            valid_ids,
            winding,
            far_field: Arc::new(AtomicBool::new(true)),
        }
    }

    /// The blended points, normalised units.
    pub fn points(&self) -> &[Point3] {
        &self.points
    }

    /// Their unit normals (zero where unusable).
    pub fn normals(&self) -> &[Point3] {
        &self.normals
    }

    /// How each point's term is fitted: `Plane`, `Quadric` or `WideQuadric`.
    pub fn fit(&self) -> LocalFit {
        self.fit
    }

    /// Point `j`'s term `(h, ∇h)` at `x = p_j + d`, `dist = |d|` (its plane, or its quadric).
    #[inline]
    fn term<const GRAD: bool>(&self, j: usize, d: Point3, dist: f64) -> (f64, Point3) {
        let n = self.normals[j];
        match self.quadrics.get(j) {
            Some(q) => q.term::<GRAD>(n, d, dist, self.radius),
            None => (dot(n, d), n),
        }
    }

    /// Flip every normal (used when the input's normals turn out to point inwards), and the far
    /// field with them when this carrier owns it (a grid shared through [`Self::with_winding`] is
    /// the caller's to orient).
    pub fn flip_normals(&mut self) {
        for n in &mut self.normals {
            *n = [-n[0], -n[1], -n[2]];
        }
        for q in &mut self.quadrics {
            q.negate();
        }
        if let Some(w) = self.winding.as_mut().and_then(Arc::get_mut) {
            w.negate();
        }
    }

    /// The switch of the winding far field (on when built): off, the carrier is the tangent planes'
    /// blend everywhere, which continues an open scan's sheet instead of closing it.
    pub fn far_field_switch(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.far_field)
    }

    /// Whether the winding far field is on (see [`Self::far_field_switch`]).
    pub fn far_field_enabled(&self) -> bool {
        self.far_field.load(Ordering::Relaxed)
    }

    /// Whether the normals point inwards: the winding number integrates to the enclosed volume
    /// with outward normals, to minus it with inward ones. `None` without a winding grid or when
    /// the integral is about zero (an open sheet seen from both sides alike).
    pub fn points_inward(&self) -> Option<bool> {
        let w = self.winding.as_ref()?;
        let (sum, abs) = w.sums();
        (abs > 0.0 && sum.abs() > 0.05 * abs).then_some(sum < 0.0)
    }

    /// The share of the space around the data where the oriented points' winding number says
    /// "enclosed" ([`WindingGrid::enclosed_share`]); `None` without a winding grid.
    pub fn enclosed_share(&self) -> Option<f64> {
        self.winding.as_ref().map(|w| w.enclosed_share())
    }

    /// `g(x)`, querying the index (the value [`Self::value_gradient`] gives, without the
    /// gradient's work).
    pub fn value(&self, x: &Point3) -> f64 {
        let mut hits = Vec::with_capacity(64);
        self.index.within(x, self.radius, &mut hits);
        self.value_with(x, &hits)
    }

    /// `(g(x), ∇g(x))`, querying the index.
    pub fn value_gradient(&self, x: &Point3) -> (f64, Point3) {
        let mut hits = Vec::with_capacity(64);
        self.index.within(x, self.radius, &mut hits);
        self.value_gradient_with(x, &hits)
    }

    /// `(g(x), ∇g(x))` given `candidates`, a superset of the points within `R` of `x`.
    pub fn value_gradient_with(&self, x: &Point3, candidates: &[u32]) -> (f64, Point3) {
        self.evaluate::<true>(x, candidates)
    }

    /// `g(x)` given `candidates` (as [`LocalCarrier::value_gradient_with`], without the gradient's
    /// work; the same value, bit for bit).
    pub fn value_with(&self, x: &Point3, candidates: &[u32]) -> f64 {
        self.evaluate::<false>(x, candidates).0
    }

    /// `g(x)` and, when `GRAD`, `∇g(x)` (else the zero vector).
    fn evaluate<const GRAD: bool>(&self, x: &Point3, candidates: &[u32]) -> (f64, Point3) {
        let r2 = self.radius * self.radius;
        let (mut within, mut nearest) = (0, (f64::INFINITY, 0usize));
        for &j in candidates {
            let j = j as usize;
            if self.normals[j] == [0.0; 3] {
                continue;
            }
            let d2 = dist2(*x, self.points[j]);
            if d2 < r2 {
                within += 1;
                if d2 < nearest.0 {
                    nearest = (d2, j);
                }
            }
        }
        if within >= FAR_NEIGHBOURS {
            let local = self.blend::<GRAD>(x, candidates, self.radius, None);
            return self.add_far_field::<GRAD>(x, local, nearest.0.sqrt(), nearest.1);
        }
        self.evaluate_widened::<GRAD>(x)
    }

    /// [`Self::evaluate`] where fewer than K usable points lie within `R` of `x`: the weights
    /// widen to the K nearest ones (found with the k-d tree).
    fn evaluate_widened<const GRAD: bool>(&self, x: &Point3) -> (f64, Point3) {
        match self.decided_far_field::<GRAD>(x) {
            Some(far) => far,
            None => self.nearest_planes_with_far_field::<GRAD>(x),
        }
    }

    /// [`Self::evaluate_widened`] through the K nearest planes, whatever the far field's weight.
    fn nearest_planes_with_far_field<const GRAD: bool>(&self, x: &Point3) -> (f64, Point3) {
        let mut knn = Vec::with_capacity(FAR_NEIGHBOURS);
        self.valid_tree.nearest_k(x, FAR_NEIGHBOURS, &mut knn);
        let (Some(&(_, d1)), Some(&(_, rho))) = (knn.first(), knn.last()) else {
            return (0.0, [0.0; 3]);
        };
        let ids: Vec<u32> = knn
            .iter()
            .map(|&(i, _)| self.valid_ids[i as usize])
            .collect();
        let local = self.blend_nearest::<GRAD>(x, &ids, rho);
        self.add_far_field::<GRAD>(x, local, d1, ids[0] as usize)
    }

    /// The blend of the planes of `ids`, the K nearest usable points of `x` by increasing
    /// distance (ties by id), `rho` the distance of the last one: weights widened to `ρ(x) = rho`
    /// (the branch of [`Self::evaluate`] where fewer than K usable points lie within `R`).
    fn blend_nearest<const GRAD: bool>(&self, x: &Point3, ids: &[u32], rho: f64) -> (f64, Point3) {
        if rho <= self.radius {
            // Fewer than K usable points exist at all (tiny clouds): plain blend over R.
            return self.blend::<GRAD>(x, ids, self.radius, None);
        }
        let far = self.points[ids[ids.len() - 1] as usize];
        let grad_rho = normalized(sub(*x, far)).unwrap_or([0.0; 3]);
        self.blend::<GRAD>(x, ids, rho, Some(grad_rho))
    }

    /// The carrier where the far field alone decides (`τ_far = 1`: at least `1.5 R` from the
    /// data and the winding number decided, `|1 − 2w| ≥ 0.6`): there
    /// [`Self::with_far_field`] gives `g = 0 · g_local + 1 · d₁ (1 − 2w)` and the planes' blend
    /// does not count, so their K-nearest query is skipped (the same value bit for bit, and the
    /// same gradient unless two points tie for the nearest). `None` elsewhere.
    fn decided_far_field<const GRAD: bool>(&self, x: &Point3) -> Option<(f64, Point3)> {
        let w = self.winding.as_ref()?;
        if !self.far_field.load(Ordering::Relaxed) {
            return None;
        }
        let (i, d1) = self.valid_tree.nearest_one(x)?;
        // The weights of `with_far_field`: "fully on" means the same there.
        if far_ramp(d1, self.radius).0 != 1.0 {
            return None;
        }
        let (wv, wg) = w.value_gradient(x);
        let a = 1.0 - 2.0 * wv;
        if far_confidence(a).0 != 1.0 {
            return None;
        }
        let g = d1 * a;
        if !GRAD {
            return Some((g, [0.0; 3]));
        }
        let nearest = self.points[self.valid_ids[i as usize] as usize];
        let dd1 = normalized(sub(*x, nearest)).unwrap_or([0.0; 3]);
        Some((g, [0, 1, 2].map(|k| d1 * (-2.0 * wg[k]) + a * dd1[k])))
    }

    /// `local` (the planes' blend at `x`) with the winding far field where it applies; `d1` is
    /// the distance from `x` to the nearest usable point, `nearest` its id.
    fn add_far_field<const GRAD: bool>(
        &self,
        x: &Point3,
        local: (f64, Point3),
        d1: f64,
        nearest: usize,
    ) -> (f64, Point3) {
        match &self.winding {
            Some(w) if d1 > GUARD_FROM * self.radius && self.far_field.load(Ordering::Relaxed) => {
                self.with_far_field::<GRAD>(x, local, w, d1, self.points[nearest])
            }
            _ => local,
        }
    }

    /// The blend of the [`FAR_NEIGHBOURS`] nearest tangent planes at `x` (without the far field).
    pub fn nearest_planes(&self, x: &Point3) -> f64 {
        let mut knn = Vec::with_capacity(FAR_NEIGHBOURS);
        self.valid_tree.nearest_k(x, FAR_NEIGHBOURS, &mut knn);
        let ids: Vec<u32> = knn
            .iter()
            .map(|&(i, _)| self.valid_ids[i as usize])
            .collect();
        let rho = knn
            .last()
            .map_or(self.radius, |&(_, d)| d.max(self.radius) * 1.0001);
        self.blend::<true>(x, &ids, rho, None).0
    }

    /// Blend the local value with the winding far field `d₁ (1 − 2w)` (about ±d₁ outside / inside):
    /// `g = (1 − τ) g_local + τ g_far`, `d₁` the distance to the nearest point. `τ` combines two
    /// hand-overs (`τ = 1 − (1 − τ_far)(1 − τ_guard)`), each scaled by the far field's confidence
    /// `c`: 1 where `w` is decisively inside or outside (`|1 − 2w| ≥ 0.6`), 0 where it is undecided
    /// (`|1 − 2w| ≤ 0.2`: beside an open sheet, across a wide hole), where the tangent planes keep
    /// deciding as before.
    /// - `τ_far = s((d₁ − R/2)/R) · c`: off the data the winding number decides.
    /// - `τ_guard = s((d₁ − R/4)/(R/2)) · c_g · D`: nearer the data, only where the planes and the
    ///   winding number disagree about the side (`D = s(−g_local (1 − 2w) / (R/8))`, 0 where they
    ///   agree). Between limbs closer than about `2R` and in concavities, the planes of the limb's far
    ///   side or of the curved part outvote the near ones and leave a stray sheet of the carrier there
    ///   (a handle); the winding number of all the oriented points knows the side. `c_g` asks `w`
    ///   to be within 0.05 of 0 or 1 (beside an open sheet it is 0.2–0.5). Where the two agree
    ///   (every sample of a clean closed surface near the data) nothing changes.
    ///
    /// `s` is the C¹ smoothstep. The data points themselves (`d₁ = 0`) see only the planes, so the
    /// offsets and the spline do not change.
    fn with_far_field<const GRAD: bool>(
        &self,
        x: &Point3,
        (gl, dl): (f64, Point3),
        w: &WindingGrid,
        d1: f64,
        nearest: Point3,
    ) -> (f64, Point3) {
        let r = self.radius;
        let (s1, ds1) = far_ramp(d1, r);
        let (s2, ds2) = smoothstep((d1 - GUARD_FROM * r) / (GUARD_WIDTH * r));
        let (wv, wg) = w.value_gradient(x);
        let a = 1.0 - 2.0 * wv;
        let (c, dc) = far_confidence(a);
        let dc_dw = dc / 0.4 * -2.0 * a.signum();
        // The guard asks more of the winding number: `w` within 0.05 of 0 or 1 (beside an open
        // sheet, e.g. under a single range image near its rim, `w` is 0.2–0.5 and the planes
        // keep deciding: the sheet stays open).
        let (cg, dcg) =
            smoothstep((a.abs() - GUARD_DECIDED.0) / (GUARD_DECIDED.1 - GUARD_DECIDED.0));
        let dcg_dw = dcg / (GUARD_DECIDED.1 - GUARD_DECIDED.0) * -2.0 * a.signum();
        let delta = GUARD_SCALE * r;
        let (dis, ddis) = smoothstep(-gl * a / delta);
        // ±d₁ where decided: distance-like (slope about 1) so the polygonizer's skip test still
        // rules out far cells.
        let gf = d1 * a;
        let dd1 = normalized(sub(*x, nearest)).unwrap_or([0.0; 3]);
        let tau_far = s1 * c;
        let tau_guard = s2 * cg * dis;
        let tau = 1.0 - (1.0 - tau_far) * (1.0 - tau_guard);
        let g = (1.0 - tau) * gl + tau * gf;
        if !GRAD {
            return (g, [0.0; 3]);
        }
        let grad = [0, 1, 2].map(|k| {
            let da = -2.0 * wg[k];
            let dt_far = ds1 / r * dd1[k] * c + s1 * dc_dw * wg[k];
            let ddis_k = ddis / delta * -(dl[k] * a + gl * da);
            let dt_guard = ds2 / (GUARD_WIDTH * r) * dd1[k] * cg * dis
                + s2 * dcg_dw * wg[k] * dis
                + s2 * cg * ddis_k;
            let dtau = (1.0 - tau_guard) * dt_far + (1.0 - tau_far) * dt_guard;
            let dgf = d1 * da + a * dd1[k];
            (1.0 - tau) * dl[k] + tau * dgf + (gf - gl) * dtau
        });
        (g, grad)
    }

    /// `g = Σ w_j n_j·(x − p_j) / Σ w_j` and its gradient over the points `ids` with
    /// `w_j = ψ(|x − p_j| / ρ)`; `grad_rho` is `∇ρ` when the radius depends on `x` (`None`: fixed).
    /// Without `GRAD` only `g` (the gradient comes back zero).
    fn blend<const GRAD: bool>(
        &self,
        x: &Point3,
        ids: &[u32],
        rho: f64,
        grad_rho: Option<Point3>,
    ) -> (f64, Point3) {
        let (r2, inv_r) = (rho * rho, 1.0 / rho);
        let (mut sw, mut swd) = (0.0, 0.0);
        let (mut sg, mut sdw) = ([0.0; 3], [0.0; 3]);
        for &j in ids {
            let j = j as usize;
            let diff = sub(*x, self.points[j]);
            let d2 = dot(diff, diff);
            let n = self.normals[j];
            if d2 >= r2 || n == [0.0; 3] {
                continue;
            }
            let d = d2.sqrt();
            let t = d * inv_r;
            let w = Kernel::WendlandC2.value(t);
            let (dist, grad_dist) = self.term::<GRAD>(j, diff, d);
            sw += w;
            swd += w * dist;
            if !GRAD {
                continue;
            }
            let dw_over = Kernel::WendlandC2.derivative_over_r(t) * inv_r * inv_r;
            // ∇ψ(|x − p|/ρ) = ψ'(t)/t · [(x − p)/ρ² − |x − p|²/ρ³ ∇ρ]
            let mut dw = [dw_over * diff[0], dw_over * diff[1], dw_over * diff[2]];
            if let Some(gr) = grad_rho {
                for k in 0..3 {
                    dw[k] -= dw_over * d2 * inv_r * gr[k];
                }
            }
            for k in 0..3 {
                sg[k] += w * grad_dist[k] + dw[k] * dist;
                sdw[k] += dw[k];
            }
        }
        if sw <= 0.0 {
            return self.nearest_plane(x);
        }
        let g = swd / sw;
        if !GRAD {
            return (g, [0.0; 3]);
        }
        (
            g,
            [
                (sg[0] - g * sdw[0]) / sw,
                (sg[1] - g * sdw[1]) / sw,
                (sg[2] - g * sdw[2]) / sw,
            ],
        )
    }

    /// Signed distance to the tangent plane of the nearest point with a usable normal.
    fn nearest_plane(&self, x: &Point3) -> (f64, Point3) {
        // Never empty: `new` refuses a carrier without a usable normal.
        let (item, _) = self.valid_tree.nearest_one(x).unwrap_or((0, 0.0));
        let j = self.valid_ids[item as usize] as usize;
        let d = sub(*x, self.points[j]);
        self.term::<true>(j, d, norm(d))
    }

    /// Support radius of the weights, normalised units.
    pub fn radius(&self) -> f64 {
        self.radius
    }
}

#[cfg(test)]
mod tests;
