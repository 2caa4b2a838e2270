//! The bumpy sphere: the star-shaped surface `ρ(u) = R (1 + a Y(u))` over unit directions `u`, with
//! the low-frequency bump `Y(u) = 0.4 P₂(z) + 0.4 (x³ − 3xy²) + 0.4 xy` (degrees 2, 3 and 2 in
//! `u = (x, y, z)`; `|Y| ≤ 0.4 + 0.4 + 0.2 = 1` on the unit sphere, so `ρ ∈ [R(1 − a), R(1 + a)]`).
//!
//! It is the zero set of `F(p) = |p − c| − R (1 + a Y(u))`, `u = (p − c)/|p − c|`, negative inside,
//! with `∇F = u − (R a / ρ)(∇Y − (u·∇Y) u)` (`∇Y` the gradient of the polynomial, `ρ = |p − c|`).
//! `F / |∇F|` is only a first-order approximation of the signed distance (exact on the surface,
//! error growing with the distance to it). Parametrised by `u`, the area element is
//! `ρ(u)² |∇F| dΩ` (because `u·∇F = 1` on the surface).

use super::SplitMix64;
use crate::geometry::{Point3, add, dot, norm, scale, sub};

/// `Y(u)` (any `u`; the bump is defined by its values on the unit sphere).
fn bump(u: Point3) -> f64 {
    let [x, y, z] = u;
    0.4 * 0.5 * (3.0 * z * z - 1.0) + 0.4 * (x * x * x - 3.0 * x * y * y) + 0.4 * x * y
}

/// `∇Y(u)`, the Euclidean gradient of the polynomial.
fn bump_gradient(u: Point3) -> Point3 {
    let [x, y, z] = u;
    [
        0.4 * (3.0 * x * x - 3.0 * y * y) + 0.4 * y,
        -2.4 * x * y + 0.4 * x,
        1.2 * z,
    ]
}

/// A rigorous bound of `|∇Y|` on the unit sphere: `|∂x|, |∂y| ≤ 1.2 + 0.4`, `|∂z| ≤ 1.2`.
const BUMP_GRADIENT_BOUND: f64 = 2.56;

/// `(F(p), ∇F(p))`; the gradient is returned as zero at the centre, where `F` is not differentiable.
pub(super) fn implicit(p: &Point3, center: Point3, radius: f64, amplitude: f64) -> (f64, Point3) {
    let d = sub(*p, center);
    let rho = norm(d);
    if rho == 0.0 {
        return (
            -radius * (1.0 + amplitude * bump([0.0, 0.0, 1.0])),
            [0.0; 3],
        );
    }
    let u = scale(d, 1.0 / rho);
    let g = bump_gradient(u);
    let tangential = sub(g, scale(u, dot(u, g)));
    let grad = sub(u, scale(tangential, radius * amplitude / rho));
    (rho - radius * (1.0 + amplitude * bump(u)), grad)
}

/// Approximate signed distance `F / |∇F|` (negative inside; exact sign, first-order magnitude).
pub(super) fn signed_distance(p: &Point3, center: Point3, radius: f64, amplitude: f64) -> f64 {
    let (f, g) = implicit(p, center, radius, amplitude);
    let gn = norm(g);
    if gn > 0.0 { f / gn } else { f }
}

/// Surface point in direction `u` (unit) and its outward unit normal.
pub(super) fn surface_point(
    u: Point3,
    center: Point3,
    radius: f64,
    amplitude: f64,
) -> (Point3, Point3) {
    let p = add(center, scale(u, radius * (1.0 + amplitude * bump(u))));
    let (_, g) = implicit(&p, center, radius, amplitude);
    (p, scale(g, 1.0 / norm(g)))
}

/// One area-uniform sample: `u` uniform on the sphere, accepted with probability
/// `ρ² |∇F| / bound`, `bound = R²(1 + a)² √(1 + (2.56 a / (1 − a))²)`.
pub(super) fn sample(
    rng: &mut SplitMix64,
    center: Point3,
    radius: f64,
    amplitude: f64,
) -> (Point3, Point3) {
    let a = amplitude.abs().min(0.99);
    let bound =
        (radius * (1.0 + a)).powi(2) * (1.0 + (BUMP_GRADIENT_BOUND * a / (1.0 - a)).powi(2)).sqrt();
    loop {
        let u = rng.next_unit_vector();
        let rho = radius * (1.0 + amplitude * bump(u));
        let p = add(center, scale(u, rho));
        let (_, g) = implicit(&p, center, radius, amplitude);
        if rng.next_f64() * bound <= rho * rho * norm(g) {
            return (p, scale(g, 1.0 / norm(g)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bump_is_bounded_and_its_gradient_is_right() {
        let mut rng = SplitMix64(3);
        for _ in 0..5000 {
            let u = rng.next_unit_vector();
            assert!(bump(u).abs() <= 1.0);
            assert!(norm(bump_gradient(u)) <= BUMP_GRADIENT_BOUND);
            let h = 1e-6;
            for k in 0..3 {
                let mut a = u;
                let mut b = u;
                a[k] += h;
                b[k] -= h;
                let fd = (bump(a) - bump(b)) / (2.0 * h);
                assert!((fd - bump_gradient(u)[k]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn implicit_gradient_matches_finite_differences_and_the_sign_is_right() {
        let (c, r, a) = ([0.5; 3], 0.35, 0.1);
        let mut rng = SplitMix64(9);
        for _ in 0..500 {
            let u = rng.next_unit_vector();
            let (p, n) = surface_point(u, c, r, a);
            assert!(implicit(&p, c, r, a).0.abs() < 1e-14);
            assert!(signed_distance(&add(p, scale(n, 1e-3)), c, r, a) > 0.0);
            assert!(signed_distance(&sub(p, scale(n, 1e-3)), c, r, a) < 0.0);
            let q = add(p, scale(u, 0.01));
            let (_, g) = implicit(&q, c, r, a);
            let h = 1e-6;
            for k in 0..3 {
                let mut x = q;
                let mut y = q;
                x[k] += h;
                y[k] -= h;
                let fd = (implicit(&x, c, r, a).0 - implicit(&y, c, r, a).0) / (2.0 * h);
                assert!((fd - g[k]).abs() < 1e-6);
            }
        }
    }
}
