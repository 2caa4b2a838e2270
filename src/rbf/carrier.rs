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
//!   and concavities keep the right sign.

use super::Kernel;
use crate::geometry::{Aabb, Point3, dist2, dot, norm, normalized, pca::pca, sub};
use crate::spatial::{KdTree, SpatialIndex};
use std::sync::Arc;

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
            Carrier::Local(l) => l.value_gradient(x).0,
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

/// Fewest points the local carrier blends at any `x` (the far field's vote, see [`LocalCarrier`]).
pub const FAR_NEIGHBOURS: usize = 16;

/// Parameters of carrier fitting.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CarrierParams {
    /// Which solid.
    pub kind: CarrierKind,
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
            LocalCarrier::new(points, normals, radius, Arc::clone(index))
                .map(Carrier::Local)
                .ok_or(CarrierError::NeedsNormals)
        }
    }
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
    radius: f64,
    index: Arc<dyn SpatialIndex + Send>,
    valid_tree: KdTree,
    valid_ids: Vec<u32>,
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
    /// Build from points, normals (same length, zero or non-finite = unusable), the support radius and an
    /// index over `points`. `None` when no normal is usable.
    pub fn new(
        points: &[Point3],
        normals: &[Point3],
        radius: f64,
        index: Arc<dyn SpatialIndex + Send>,
    ) -> Option<Self> {
        let normals: Vec<Point3> = normals
            .iter()
            .map(|n| normalized(*n).unwrap_or([0.0; 3]))
            .collect();
        Self::from_parts(points.to_vec(), normals, radius, index)
    }

    /// Rebuild from saved parts: the points, their unit normals exactly as [`Self::normals`] gave
    /// them (not renormalised, so a loaded carrier evaluates bit for bit like the saved one), the
    /// radius and an index over `points`. `None` when no normal is usable or the lengths differ.
    pub fn from_parts(
        points: Vec<Point3>,
        normals: Vec<Point3>,
        radius: f64,
        index: Arc<dyn SpatialIndex + Send>,
    ) -> Option<Self> {
        let valid_ids: Vec<u32> = (0..points.len() as u32)
            .filter(|&i| normals[i as usize] != [0.0; 3])
            .collect();
        if valid_ids.is_empty() || normals.len() != points.len() {
            return None;
        }
        let valid_points: Vec<Point3> = valid_ids.iter().map(|&i| points[i as usize]).collect();
        let valid_tree = KdTree::build(&valid_points).ok()?;
        Some(LocalCarrier {
            points,
            normals,
            radius,
            index,
            valid_tree,
            valid_ids,
        })
    }

    /// The blended points, normalised units.
    pub fn points(&self) -> &[Point3] {
        &self.points
    }

    /// Their unit normals (zero where unusable).
    pub fn normals(&self) -> &[Point3] {
        &self.normals
    }

    /// Flip every normal (used when the input's normals turn out to point inwards).
    pub fn flip_normals(&mut self) {
        for n in &mut self.normals {
            *n = [-n[0], -n[1], -n[2]];
        }
    }

    /// `(g(x), ∇g(x))`, querying the index.
    pub fn value_gradient(&self, x: &Point3) -> (f64, Point3) {
        let mut hits = Vec::with_capacity(64);
        self.index.within(x, self.radius, &mut hits);
        self.value_gradient_with(x, &hits)
    }

    /// `(g(x), ∇g(x))` given `candidates`, a superset of the points within `R` of `x`.
    pub fn value_gradient_with(&self, x: &Point3, candidates: &[u32]) -> (f64, Point3) {
        let r2 = self.radius * self.radius;
        let within = candidates
            .iter()
            .filter(|&&j| {
                let j = j as usize;
                self.normals[j] != [0.0; 3] && dist2(*x, self.points[j]) < r2
            })
            .count();
        if within >= FAR_NEIGHBOURS {
            return self.blend(x, candidates, self.radius, None);
        }
        // Fewer than K usable points within R: widen the weights to the K nearest ones.
        let mut knn = Vec::with_capacity(FAR_NEIGHBOURS);
        self.valid_tree.nearest_k(x, FAR_NEIGHBOURS, &mut knn);
        let Some(&(kth, rho)) = knn.last() else {
            return (0.0, [0.0; 3]);
        };
        let ids: Vec<u32> = knn
            .iter()
            .map(|&(i, _)| self.valid_ids[i as usize])
            .collect();
        if rho <= self.radius {
            // Fewer than K usable points exist at all (tiny clouds): plain blend over R.
            return self.blend(x, &ids, self.radius, None);
        }
        let far = self.points[self.valid_ids[kth as usize] as usize];
        let grad_rho = normalized(sub(*x, far)).unwrap_or([0.0; 3]);
        self.blend(x, &ids, rho, Some(grad_rho))
    }

    /// `g = Σ w_j n_j·(x − p_j) / Σ w_j` and its gradient over the points `ids` with
    /// `w_j = ψ(|x − p_j| / ρ)`; `grad_rho` is `∇ρ` when the radius depends on `x` (`None`: fixed).
    fn blend(&self, x: &Point3, ids: &[u32], rho: f64, grad_rho: Option<Point3>) -> (f64, Point3) {
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
            let t = d2.sqrt() * inv_r;
            let w = Kernel::WendlandC2.value(t);
            let dw_over = Kernel::WendlandC2.derivative_over_r(t) * inv_r * inv_r;
            // ∇ψ(|x − p|/ρ) = ψ'(t)/t · [(x − p)/ρ² − |x − p|²/ρ³ ∇ρ]
            let mut dw = [dw_over * diff[0], dw_over * diff[1], dw_over * diff[2]];
            if let Some(gr) = grad_rho {
                for k in 0..3 {
                    dw[k] -= dw_over * d2 * inv_r * gr[k];
                }
            }
            let dist = dot(n, diff);
            sw += w;
            swd += w * dist;
            for k in 0..3 {
                sg[k] += w * n[k] + dw[k] * dist;
                sdw[k] += dw[k];
            }
        }
        if sw <= 0.0 {
            return self.nearest_plane(x);
        }
        let g = swd / sw;
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
        (
            dot(self.normals[j], sub(*x, self.points[j])),
            self.normals[j],
        )
    }

    /// Support radius of the weights, normalised units.
    pub fn radius(&self) -> f64 {
        self.radius
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_points(n: usize, c: Point3, r: f64) -> (Vec<Point3>, Vec<Point3>) {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let rr = (1.0 - z * z).sqrt();
                let t = golden * i as f64;
                let u = [rr * t.cos(), rr * t.sin(), z];
                ([c[0] + r * u[0], c[1] + r * u[1], c[2] + r * u[2]], u)
            })
            .unzip()
    }

    fn local(p: &[Point3], n: &[Point3], r: f64) -> LocalCarrier {
        let index: Arc<dyn SpatialIndex + Send> = Arc::from(
            crate::spatial::build_index(p, crate::spatial::IndexKind::KdTree, 16).unwrap(),
        );
        LocalCarrier::new(p, n, r, index).unwrap()
    }

    #[test]
    fn sphere_fit_recovers_center_and_radius() {
        let (p, _) = sphere_points(500, [0.3, 0.5, 0.6], 0.25);
        let Carrier::Sphere { center, radius } = fit_sphere(&p) else {
            panic!()
        };
        assert!(norm(sub(center, [0.3, 0.5, 0.6])) < 1e-9);
        assert!((radius - 0.25).abs() < 1e-9);
    }

    #[test]
    fn ellipsoid_fit_of_a_sphere_is_the_sphere() {
        let (p, _) = sphere_points(4000, [0.5; 3], 0.4);
        let c = fit_ellipsoid(&p).unwrap();
        for q in &p {
            assert!(c.value(q).abs() < 5e-3, "{}", c.value(q));
        }
        assert!(c.value(&[0.5; 3]) < 0.0 && c.value(&[1.5, 0.5, 0.5]) > 0.0);
    }

    #[test]
    fn flat_points_make_the_ellipsoid_refuse() {
        let p: Vec<Point3> = (0..100)
            .map(|i| [(i % 10) as f64, (i / 10) as f64, 0.0])
            .collect();
        assert!(matches!(
            fit_ellipsoid(&p),
            Err(CarrierError::Degenerate { .. })
        ));
    }

    #[test]
    fn analytic_gradients_match_finite_differences() {
        let (p, n) = sphere_points(800, [0.5; 3], 0.3);
        let carriers = [
            fit_sphere(&p),
            Carrier::Ellipsoid {
                center: [0.5; 3],
                axes: [[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [0.0, -0.8, 0.6]],
                semi_axes: [0.4, 0.3, 0.2],
            },
            Carrier::Local(local(&p, &n, 0.08)),
        ];
        for c in &carriers {
            for x in [[0.71, 0.52, 0.48], [0.2, 0.33, 0.61], [0.5, 0.9, 0.4]] {
                let g = c.gradient(&x);
                let h = 1e-6;
                for k in 0..3 {
                    let (mut a, mut b) = (x, x);
                    a[k] += h;
                    b[k] -= h;
                    let fd = (c.value(&a) - c.value(&b)) / (2.0 * h);
                    let tol = 1e-5;
                    assert!(
                        (fd - g[k]).abs() < tol,
                        "{} k={k}: fd {fd} vs {}",
                        c.name(),
                        g[k]
                    );
                }
            }
        }
    }

    #[test]
    fn one_bad_normal_makes_no_pocket_off_the_data() {
        // A sphere of radius 0.3 with one normal turned 87° (as PCA gives on a thin ear): off the
        // data, beyond the band R, the carrier must stay positive outside the sphere.
        let (p, mut n) = sphere_points(2000, [0.5; 3], 0.3);
        let bad = 1000;
        let u = n[bad];
        let t = normalized([u[1], -u[0], 0.0]).unwrap();
        n[bad] = normalized([0.05 * u[0] + t[0], 0.05 * u[1] + t[1], 0.05 * u[2] + t[2]]).unwrap();
        let r = 0.04;
        let c = local(&p, &n, r);
        for s in [1.2, 1.6, 2.5, 4.0] {
            for dir in [t, [-t[0], -t[1], -t[2]]] {
                // Off the bad point, outward by s·R and sideways along its wrong plane.
                let x = [
                    p[bad][0] + s * r * (u[0] + 0.3 * dir[0]),
                    p[bad][1] + s * r * (u[1] + 0.3 * dir[1]),
                    p[bad][2] + s * r * (u[2] + 0.3 * dir[2]),
                ];
                let outside = norm(sub(x, [0.5; 3])) - 0.3;
                assert!(outside > 0.0);
                let (g, _) = c.value_gradient(&x);
                assert!(g > 0.0, "g = {g} at {x:?}, {outside} outside the sphere");
            }
        }
    }

    #[test]
    fn local_carrier_has_the_sign_of_the_solid() {
        let (p, n) = sphere_points(2000, [0.5; 3], 0.3);
        let c = local(&p, &n, 0.08);
        for (x, inside) in [
            ([0.5, 0.5, 0.5], true),
            ([0.5, 0.5, 0.75], true),
            ([0.5, 0.5, 0.85], false),
            ([0.0, 0.0, 0.0], false),
        ] {
            let (g, _) = c.value_gradient(&x);
            assert_eq!(g < 0.0, inside, "g({x:?}) = {g}");
        }
        let max_off = p
            .iter()
            .map(|q| c.value_gradient(q).0.abs())
            .fold(0.0, f64::max);
        // Planes of a sphere of radius 0.3 blended over R = 0.08 miss the data by ~κR²/10.
        assert!(
            max_off < 0.05 * 0.08,
            "offsets at the data should be small, got {max_off}"
        );
    }
}
