//! Local quadrics for the local carrier's planes (Ohtake et al. 2003, "Multi-level partition of
//! unity implicits", use local quadrics the same way): at every oriented point `p` a height field
//! `w = c₀ + c₁u + c₂v + c₃u² + c₄uv + c₅v²` over its tangent frame `(u, v, w)` (normal `n` = `w`)
//! is fitted by weighted least squares to the usable points within `R` whose normals agree with
//! `n` (`n·n_k ≥` [`SAME_SIDE`]: the far side of a thin part or of a narrow gap is left out),
//! weights Wendland `ψ(|p_k − p|/R)`. The carrier's term of `p` is then
//! `h(x) = n·d − τ(|d|/R) (e₀ + l·d + dᵀQd)`, `d = x − p`, instead of the plane's `n·d`:
//! it follows the surface's curvature, so the data points' offsets (what the spline has to make
//! up) shrink to the fitting error (on a sampled sphere 8.4e-4 → 2.7e-6 normalised units, see the
//! tests) and the surface between the points follows the curvature instead of the spline's bumps.
//! `c₀` also averages the points' noise over the fit.
//! `τ` is 1 up to `R` and fades smoothly (C¹) to the plane by `2R`, where the weights widen
//! beyond `R` (sparse parts, off the data).
//!
//! A fit that is ill-posed (fewer than [`MIN_POINTS`] agreeing points, a singular system, or a
//! tilt or curvature no sampled surface at this radius has) leaves the plane. `O(n k)`.
//!
//! [`LocalFit::WideQuadric`] fits the same quadric over `2R` (weights `ψ(d/2R)`): on noisy data
//! the fit then averages about four times the points (chosen by `auto` when the noise estimate
//! finds noise); the term is evaluated and faded as above.

use crate::geometry::{Point3, dot, norm, sub};
use crate::rbf::Kernel;
use crate::spatial::SpatialIndex;
use rayon::prelude::*;

/// How each oriented point's term of the local carrier is fitted (this module).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LocalFit {
    /// `quadric` on clean data, `wide-quadric` where the noise estimate finds noise (a quadric
    /// over the support radius follows the noise; one over twice the radius averages it).
    #[default]
    Auto,
    /// The tangent plane `n·(x − p)` (Hoppe et al. 1992).
    Plane,
    /// A local quadric height field over the tangent plane, fitted to the points within `R`
    /// whose normals agree (Ohtake et al. 2003).
    Quadric,
    /// The same quadric fitted over [`WIDE_FIT`] times the support radius (about four times
    /// the points): its offset and curvature average the noise instead of following it.
    WideQuadric,
}

impl LocalFit {
    /// Every choice, in the order the command line lists them.
    pub const ALL: [LocalFit; 4] = [
        LocalFit::Auto,
        LocalFit::Plane,
        LocalFit::Quadric,
        LocalFit::WideQuadric,
    ];

    /// The radius the quadrics are fitted over, as a multiple of the support radius (`None`:
    /// planes, nothing fitted; `Auto` counts as `Quadric`).
    pub fn fit_scale(self) -> Option<f64> {
        match self {
            LocalFit::Plane => None,
            LocalFit::Auto | LocalFit::Quadric => Some(1.0),
            LocalFit::WideQuadric => Some(WIDE_FIT),
        }
    }

    /// Command-line / report name.
    pub fn name(self) -> &'static str {
        match self {
            LocalFit::Auto => "auto",
            LocalFit::Plane => "plane",
            LocalFit::Quadric => "quadric",
            LocalFit::WideQuadric => "wide-quadric",
        }
    }

    /// `Auto` resolved: `WideQuadric` for noisy data, else `Quadric`; explicit choices unchanged.
    pub fn resolve(self, noisy: bool) -> LocalFit {
        match self {
            LocalFit::Auto if noisy => LocalFit::WideQuadric,
            LocalFit::Auto => LocalFit::Quadric,
            f => f,
        }
    }
}

impl std::fmt::Display for LocalFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for LocalFit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!("unknown local fit '{s}' (use auto, plane, quadric or wide-quadric)")
            })
    }
}

/// The wide quadrics' fit radius in support radii (measured on noisy scans: 2 brings the
/// noisy armadillo, bunny and 10⁶ torus to screened Poisson's Chamfer, see docs/robustness.md).
pub const WIDE_FIT: f64 = 2.0;
/// Least cosine between a point's normal and a neighbour's for the neighbour to enter its fit.
pub const SAME_SIDE: f64 = 0.5;
/// Fewest agreeing points (the point itself included) for a quadric; fewer leave the plane.
pub const MIN_POINTS: usize = 10;
/// Largest tilt `|(c₁, c₂)|` of a fit (the plane's normal more than 45° off: a bad fit).
const MAX_TILT: f64 = 1.0;
/// Largest curvature coefficient `|c₃|, |c₄|/2, |c₅|` in units of one over the fit radius
/// (radius of curvature `R/8` over R: not resolvable by points spaced about `R/3`; `R/2` for the
/// wide fits over 2R, which are meant to smooth).
const MAX_CURVATURE: f64 = 4.0;
/// `MONOMIAL[a][b]`: the moment of `φ_a φ_b` (basis `1, u, v, u², uv, v²`) among the 15 monomials
/// `1, u, v, u², uv, v², u³, u²v, uv², v³, u⁴, u³v, u²v², uv³, v⁴`.
const MONOMIAL: [[usize; 6]; 6] = [
    [0, 1, 2, 3, 4, 5],
    [1, 3, 4, 6, 7, 8],
    [2, 4, 5, 7, 8, 9],
    [3, 6, 7, 10, 11, 12],
    [4, 7, 8, 11, 12, 13],
    [5, 8, 9, 12, 13, 14],
];
/// Ridge on the quadratic coefficients, relative to the total weight.
const RIDGE: f64 = 1e-3;

/// The correction of one point's plane, in world (normalised) units: `e₀ + l·d + dᵀQd`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Quadric {
    /// Offset along the normal.
    pub e0: f64,
    /// Linear term (in the tangent plane).
    pub l: Point3,
    /// Symmetric quadratic form `[xx, xy, xz, yy, yz, zz]`.
    pub q: [f64; 6],
}

impl Quadric {
    /// Negate (the normal flipped).
    pub fn negate(&mut self) {
        self.e0 = -self.e0;
        self.l = self.l.map(|v| -v);
        self.q = self.q.map(|v| -v);
    }

    /// `(h, ∇h)` at offset `d = x − p` from the point (`dist = |d|`), with normal `n`, support
    /// radius `r`; without `GRAD` the gradient is zero.
    #[inline]
    pub fn term<const GRAD: bool>(&self, n: Point3, d: Point3, dist: f64, r: f64) -> (f64, Point3) {
        let plane = dot(n, d);
        let q = &self.q;
        let qd = [
            q[0] * d[0] + q[1] * d[1] + q[2] * d[2],
            q[1] * d[0] + q[3] * d[1] + q[4] * d[2],
            q[2] * d[0] + q[4] * d[1] + q[5] * d[2],
        ];
        let corr = self.e0 + dot(self.l, d) + dot(qd, d);
        let t = dist / r;
        let (tau, dtau) = taper(t);
        let h = plane - tau * corr;
        if !GRAD {
            return (h, [0.0; 3]);
        }
        let mut g = [0.0; 3];
        for k in 0..3 {
            g[k] = n[k] - tau * (self.l[k] + 2.0 * qd[k]);
        }
        if dtau != 0.0 && dist > 0.0 {
            let s = dtau * corr / (r * dist);
            for k in 0..3 {
                g[k] -= s * d[k];
            }
        }
        (h, g)
    }
}

/// `(τ(t), τ'(t))`: 1 up to `t = 1`, a C¹ smoothstep down to 0 at `t = 2`.
#[inline]
fn taper(t: f64) -> (f64, f64) {
    if t <= 1.0 {
        (1.0, 0.0)
    } else if t >= 2.0 {
        (0.0, 0.0)
    } else {
        let u = t - 1.0;
        (1.0 - u * u * (3.0 - 2.0 * u), -6.0 * u * (1.0 - u))
    }
}

/// Fit the quadric of every point with a usable (unit, non-zero) normal over the points within
/// `radius` found with `index`; unusable points and ill-posed fits get the plane.
pub fn fit_quadrics(
    points: &[Point3],
    normals: &[Point3],
    radius: f64,
    index: &(dyn SpatialIndex + Send),
) -> Vec<Quadric> {
    (0..points.len())
        .into_par_iter()
        .map_init(Vec::new, |hits, j| {
            if normals[j] == [0.0; 3] {
                return Quadric::default();
            }
            index.within(&points[j], radius, hits);
            hits.sort_unstable();
            fit_one(points, normals, j, hits, radius).unwrap_or_default()
        })
        .collect()
}

/// Orthonormal tangent frame of the unit normal `n` (deterministic).
fn frame(n: Point3) -> (Point3, Point3) {
    let a = if n[0].abs() < 0.6 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let t1 = crate::geometry::normalized(crate::geometry::cross(n, a)).unwrap_or([0.0, 0.0, 1.0]);
    (t1, crate::geometry::cross(n, t1))
}

#[allow(clippy::needless_range_loop)] // index loops mirror the normal equations
fn fit_one(
    points: &[Point3],
    normals: &[Point3],
    j: usize,
    hits: &[u32],
    radius: f64,
) -> Option<Quadric> {
    let (p, n) = (points[j], normals[j]);
    let (t1, t2) = frame(n);
    let inv_r = 1.0 / radius;
    // The normal equations from weighted moments: `mo[k]` = Σ ω u^a v^b for the 15 monomials of
    // degree ≤ 4 (see `MONOMIAL`), `rhs` = Σ ω w φ for the basis `φ = (1, u, v, u², uv, v²)`.
    let mut mo = [0.0f64; 15];
    let mut rhs = [0.0f64; 6];
    let (mut count, mut total) = (0usize, 0.0);
    for &k in hits {
        let k = k as usize;
        let nk = normals[k];
        if nk == [0.0; 3] || dot(n, nk) < SAME_SIDE {
            continue;
        }
        let d = sub(points[k], p);
        let (u, v, w) = (dot(t1, d) * inv_r, dot(t2, d) * inv_r, dot(n, d) * inv_r);
        let omega = Kernel::WendlandC2.value(norm(d) * inv_r);
        if omega <= 0.0 {
            continue;
        }
        let (a1u, a1v) = (omega * u, omega * v);
        let (a2uu, a2uv, a2vv) = (a1u * u, a1u * v, a1v * v);
        let (a3uuu, a3uuv, a3uvv, a3vvv) = (a2uu * u, a2uu * v, a2uv * v, a2vv * v);
        let terms = [
            omega,
            a1u,
            a1v,
            a2uu,
            a2uv,
            a2vv,
            a3uuu,
            a3uuv,
            a3uvv,
            a3vvv,
            a3uuu * u,
            a3uuu * v,
            a3uuv * v,
            a3uvv * v,
            a3vvv * v,
        ];
        for (m, t) in mo.iter_mut().zip(terms) {
            *m += t;
        }
        for (r, t) in rhs.iter_mut().zip(&terms[..6]) {
            *r += t * w;
        }
        count += 1;
        total += omega;
    }
    if count < MIN_POINTS {
        return None;
    }
    let mut m = [[0.0f64; 6]; 6];
    for a in 0..6 {
        for b in 0..6 {
            m[a][b] = mo[MONOMIAL[a][b]];
        }
        if a >= 3 {
            m[a][a] += RIDGE * total;
        }
    }
    let c = crate::linalg::small::cholesky_solve(&m, &rhs).ok()?;
    let tilt = (c[1] * c[1] + c[2] * c[2]).sqrt();
    let curv = c[3].abs().max(c[5].abs()).max(0.5 * c[4].abs());
    if !(tilt <= MAX_TILT && curv <= MAX_CURVATURE) || c.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let e0 = c[0] * radius;
    let l = [0, 1, 2].map(|k| c[1] * t1[k] + c[2] * t2[k]);
    let sym = |a: usize, b: usize| {
        inv_r
            * (c[3] * t1[a] * t1[b]
                + 0.5 * c[4] * (t1[a] * t2[b] + t2[a] * t1[b])
                + c[5] * t2[a] * t2[b])
    };
    Some(Quadric {
        e0,
        l,
        q: [
            sym(0, 0),
            sym(0, 1),
            sym(0, 2),
            sym(1, 1),
            sym(1, 2),
            sym(2, 2),
        ],
    })
}
