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

use crate::geometry::{Aabb, Point3, dot, norm, normalized, pca::pca, sub};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZero;

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
    #[error("the local carrier needs oriented normals and the input has none: use --carrier ellipsoid or sphere")]
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
            Carrier::Ellipsoid { center, axes, semi_axes } => {
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
            Carrier::Ellipsoid { center, axes, semi_axes } => {
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
            Carrier::Sphere { center, radius } => Some(Aabb { min: *center, max: *center }.inflated(*radius)),
            Carrier::Ellipsoid { center, semi_axes, .. } => {
                let a = semi_axes[0].max(semi_axes[1]).max(semi_axes[2]);
                Some(Aabb { min: *center, max: *center }.inflated(a))
            }
            Carrier::Local(_) => None,
        }
    }
}

fn min3(a: &[f64; 3]) -> f64 {
    a[0].min(a[1]).min(a[2])
}

fn ellipsoid_local(x: &Point3, c: &Point3, axes: &[Point3; 3], semi: &[f64; 3]) -> (Point3, Point3) {
    let d = sub(*x, *c);
    let u = [dot(d, axes[0]), dot(d, axes[1]), dot(d, axes[2])];
    ([u[0] / semi[0], u[1] / semi[1], u[2] / semi[2]], u)
}

/// Parameters of carrier fitting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarrierParams {
    /// Which solid.
    pub kind: CarrierKind,
    /// Neighbours blended by the local carrier (default 10; 6–20 is sensible).
    pub local_neighbours: usize,
}

impl Default for CarrierParams {
    fn default() -> Self {
        CarrierParams { kind: CarrierKind::Auto, local_neighbours: 10 }
    }
}

/// Fit the carrier to normalised `points` (with unit `normals` when known).
pub fn fit_carrier(
    points: &[Point3],
    normals: Option<&[Point3]>,
    params: &CarrierParams,
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
            LocalCarrier::new(points, normals, params.local_neighbours)
                .map(Carrier::Local)
                .ok_or(CarrierError::NeedsNormals)
        }
    }
}

/// Least-squares (Kåsa) sphere; bounding sphere when the fit is degenerate.
pub fn fit_sphere(points: &[Point3]) -> Carrier {
    let bbox = Aabb::from_points(points);
    let fallback = Carrier::Sphere { center: bbox.center(), radius: 0.5 * bbox.diagonal() };
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
    let Some(sol) = gauss4(m) else { return fallback };
    let center = [sol[0] + o[0], sol[1] + o[1], sol[2] + o[2]];
    let ms: f64 = points.iter().map(|p| dot(sub(*p, center), sub(*p, center))).sum::<f64>();
    let radius = (ms / points.len() as f64).sqrt();
    if !radius.is_finite() || radius <= 0.0 || norm(sub(center, o)) > 10.0 * bbox.diagonal() {
        return fallback;
    }
    Carrier::Sphere { center, radius }
}

/// Solve a 4×4 system given as an augmented matrix; `None` when (nearly) singular.
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
    Some([m[0][4] / m[0][0], m[1][4] / m[1][1], m[2][4] / m[2][2], m[3][4] / m[3][3]])
}

/// PCA ellipsoid.
pub fn fit_ellipsoid(points: &[Point3]) -> Result<Carrier, CarrierError> {
    let p = pca(points);
    let semi_axes = p.variances.map(|v| (3.0 * v.max(0.0)).sqrt());
    if semi_axes[2] <= 1e-6 * semi_axes[0].max(f64::MIN_POSITIVE) {
        return Err(CarrierError::Degenerate { semi_axes });
    }
    Ok(Carrier::Ellipsoid { center: p.centroid, axes: p.axes, semi_axes })
}

/// Partition of unity of the tangent planes of the `k` nearest oriented points:
/// `g(x) = Σ w_j n_j·(x − p_j) / Σ w_j`, `w_j = ψ(|x − p_j| / h(x))` with ψ the Wendland C² kernel
/// and `h(x)` the distance to the (k+1)-th nearest point, so a point entering or leaving the
/// neighbourhood does so with weight 0 and `g` is continuous everywhere.
#[derive(Debug)]
pub struct LocalCarrier {
    points: Vec<Point3>,
    normals: Vec<Point3>,
    tree: ImmutableKdTree<f64, 3>,
    k: usize,
}

impl LocalCarrier {
    /// Build from points and normals (same length). Points whose normal is zero or non-finite are left
    /// out of the carrier (they still are interpolation centres). `None` when no point has a normal.
    pub fn new(points: &[Point3], normals: &[Point3], k: usize) -> Option<Self> {
        let (points, normals): (Vec<Point3>, Vec<Point3>) = points
            .iter()
            .zip(normals)
            .filter_map(|(p, n)| normalized(*n).map(|n| (*p, n)))
            .unzip();
        if points.is_empty() {
            return None;
        }
        let tree = ImmutableKdTree::new_from_slice(&points).ok()?;
        Some(LocalCarrier { k: k.clamp(1, points.len()), points, normals, tree })
    }

    /// Flip every normal (used when the input's normals turn out to point inwards).
    pub fn flip_normals(&mut self) {
        for n in &mut self.normals {
            *n = [-n[0], -n[1], -n[2]];
        }
    }

    /// `(g(x), ∇g(x))`; the gradient treats `h(x)` as locally constant.
    pub fn value_gradient(&self, x: &Point3) -> (f64, Point3) {
        let want = (self.k + 1).min(self.points.len());
        let nn = self.tree.query(x).nearest_n::<SquaredEuclidean<f64>>(NonZero::new(want).unwrap_or(NonZero::<usize>::MIN)).execute();
        let far = nn.last().map_or(0.0, |it| it.distance.sqrt());
        let h = if nn.len() > self.k { far } else { 1.5 * far + 1e-12 };
        let (mut sw, mut swd) = (0.0, 0.0);
        let (mut sg, mut sdw) = ([0.0; 3], [0.0; 3]);
        for it in nn.iter().take(self.k) {
            let j = it.item as usize;
            let d = it.distance.sqrt();
            let t = if h > 0.0 { d / h } else { 0.0 };
            let w = crate::rbf::Kernel::WendlandC2.value(t);
            let dw_over = crate::rbf::Kernel::WendlandC2.derivative_over_r(t) / (h * h).max(1e-300);
            let diff = sub(*x, self.points[j]);
            let dist = dot(self.normals[j], diff);
            sw += w;
            swd += w * dist;
            for k in 0..3 {
                sg[k] += w * self.normals[j][k] + dw_over * diff[k] * dist;
                sdw[k] += dw_over * diff[k];
            }
        }
        if sw <= 1e-300 {
            // Degenerate weights (all neighbours equidistant at h): nearest plane alone.
            let j = nn.first().map_or(0, |it| it.item as usize);
            return (dot(self.normals[j], sub(*x, self.points[j])), self.normals[j]);
        }
        let g = swd / sw;
        let grad = [(sg[0] - g * sdw[0]) / sw, (sg[1] - g * sdw[1]) / sw, (sg[2] - g * sdw[2]) / sw];
        (g, grad)
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

    #[test]
    fn sphere_fit_recovers_center_and_radius() {
        let (p, _) = sphere_points(500, [0.3, 0.5, 0.6], 0.25);
        let Carrier::Sphere { center, radius } = fit_sphere(&p) else { panic!() };
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
        let p: Vec<Point3> = (0..100).map(|i| [(i % 10) as f64, (i / 10) as f64, 0.0]).collect();
        assert!(matches!(fit_ellipsoid(&p), Err(CarrierError::Degenerate { .. })));
    }

    #[test]
    fn analytic_gradients_match_finite_differences() {
        let (p, n) = sphere_points(800, [0.5; 3], 0.3);
        let carriers = [
            fit_sphere(&p),
            Carrier::Ellipsoid { center: [0.5; 3], axes: [[1.0, 0.0, 0.0], [0.0, 0.6, 0.8], [0.0, -0.8, 0.6]], semi_axes: [0.4, 0.3, 0.2] },
            Carrier::Local(LocalCarrier::new(&p, &n, 10).unwrap()),
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
                    let tol = if matches!(c, Carrier::Local(_)) { 0.05 } else { 1e-6 };
                    assert!((fd - g[k]).abs() < tol, "{} k={k}: fd {fd} vs {}", c.name(), g[k]);
                }
            }
        }
    }

    #[test]
    fn local_carrier_has_the_sign_of_the_solid() {
        let (p, n) = sphere_points(2000, [0.5; 3], 0.3);
        let c = LocalCarrier::new(&p, &n, 10).unwrap();
        for (x, inside) in [([0.5, 0.5, 0.5], true), ([0.5, 0.5, 0.75], true), ([0.5, 0.5, 0.85], false), ([0.0, 0.0, 0.0], false)] {
            let (g, _) = c.value_gradient(&x);
            assert_eq!(g < 0.0, inside, "g({x:?}) = {g}");
        }
        let max_off = p.iter().map(|q| c.value_gradient(q).0.abs()).fold(0.0, f64::max);
        assert!(max_off < 1e-3, "offsets at the data should be small, got {max_off}");
    }
}
