//! The trefoil-knot tube: centre line `c(t) = (sin t + 2 sin 2t, cos t − 2 cos 2t, −sin 3t)`,
//! `t ∈ [0, 2π)`, centred on its bounding box, scaled, and swept by a circle of radius `tube` in the
//! Frenet frame (the trefoil's curvature never vanishes, so the frame is smooth and periodic).
//!
//! Closed forms used below: `|c'|² = 17 + 8 cos 3t + 9 cos² 3t` (so `3.90 ≤ |c'| ≤ √34`),
//! curvature `κ = |c' × c''| / |c'|³ ≤ 0.78` in trefoil units, the length of the centre line
//! `≈ 28.826` trefoil units, and the distance between strands `≥ 1.21` trefoil units: a tube of radius
//! `< 0.6` trefoil units does not intersect itself. The surface is
//! `X(t, v) = c(t) + tube (cos v N(t) + sin v B(t))` with outward normal `cos v N + sin v B` and area
//! element `tube |c'(t)| (1 − κ(t) tube cos v) dt dv` (the torsion terms are parallel to `X_v`).

use super::SplitMix64;
use crate::geometry::{Point3, add, cross, norm, scale, sub};
use std::f64::consts::TAU;

/// The y-coordinate of the centre of the trefoil's bounding box (x and z are symmetric about 0):
/// `y ∈ [−3, 2.0625]`, the maximum at `cos t = 1/8`.
const CURVE_CENTER_Y: f64 = -0.46875;

/// Samples in the coarse nearest-point search of [`distance_to_centre_line`].
const SEARCH_SAMPLES: usize = 1024;

/// The trefoil centre line in trefoil units, centred on its bounding box.
fn curve(t: f64) -> Point3 {
    [
        t.sin() + 2.0 * (2.0 * t).sin(),
        t.cos() - 2.0 * (2.0 * t).cos() - CURVE_CENTER_Y,
        -(3.0 * t).sin(),
    ]
}

/// `c'(t)`.
fn d1(t: f64) -> Point3 {
    [
        t.cos() + 4.0 * (2.0 * t).cos(),
        -t.sin() + 4.0 * (2.0 * t).sin(),
        -3.0 * (3.0 * t).cos(),
    ]
}

/// `c''(t)`.
fn d2(t: f64) -> Point3 {
    [
        -t.sin() - 8.0 * (2.0 * t).sin(),
        -t.cos() + 8.0 * (2.0 * t).cos(),
        9.0 * (3.0 * t).sin(),
    ]
}

/// Speed `|c'(t)|` in trefoil units: `√(17 + 8 cos 3t + 9 cos² 3t)`.
pub(super) fn speed(t: f64) -> f64 {
    let c = (3.0 * t).cos();
    (17.0 + 8.0 * c + 9.0 * c * c).sqrt()
}

/// Frenet frame and curvature (trefoil units) at `t`.
struct Frenet {
    normal: Point3,
    binormal: Point3,
    curvature: f64,
}

fn frenet(t: f64) -> Frenet {
    let v = d1(t);
    let b = cross(v, d2(t));
    let s = norm(v);
    let nb = norm(b);
    let tangent = scale(v, 1.0 / s);
    let binormal = scale(b, 1.0 / nb);
    Frenet {
        normal: cross(binormal, tangent),
        binormal,
        curvature: nb / (s * s * s),
    }
}

/// Point and outward unit normal of the tube surface at `(t, v)`; `tube` is in output units, the
/// centre line is `center + scale_factor · c(t)`.
pub(super) fn surface_point(
    center: Point3,
    scale_factor: f64,
    tube: f64,
    t: f64,
    v: f64,
) -> (Point3, Point3) {
    let f = frenet(t);
    let n = add(scale(f.normal, v.cos()), scale(f.binormal, v.sin()));
    let c = add(center, scale(curve(t), scale_factor));
    (add(c, scale(n, tube)), n)
}

/// One area-uniform sample (rejection on the area element, whose maximum is bounded by
/// `√34 · (1 + κ_max tube / scale)` with the rigorous bound `κ ≤ √162 / (17 − 16/9) ≤ 0.84`).
pub(super) fn sample(
    rng: &mut SplitMix64,
    center: Point3,
    scale_factor: f64,
    tube: f64,
) -> (Point3, Point3) {
    let r = tube / scale_factor;
    let bound = 34f64.sqrt() * (1.0 + 0.84 * r);
    loop {
        let t = rng.next_f64() * TAU;
        let v = rng.next_f64() * TAU;
        let f = frenet(t);
        let w = speed(t) * (1.0 - f.curvature * r * v.cos());
        if rng.next_f64() * bound <= w {
            return surface_point(center, scale_factor, tube, t, v);
        }
    }
}

/// Distance from `p` to the scaled centre line (output units): the best of [`SEARCH_SAMPLES`]
/// equally spaced parameters, refined by golden-section search within one spacing on either side.
/// Exact to rounding wherever the nearest point of the curve is unique and lies in that bracket —
/// in particular within the tube (`distance < 0.6 · scale`); an approximation farther away.
pub(super) fn distance_to_centre_line(p: &Point3, center: Point3, scale_factor: f64) -> f64 {
    // Work in trefoil units; the coarse pass steps e^{ikt} by complex rotation (no trig per sample).
    let q = scale(sub(*p, center), 1.0 / scale_factor);
    let dt = TAU / SEARCH_SAMPLES as f64;
    let (sd, cd) = dt.sin_cos();
    let (mut c1, mut s1) = (1.0f64, 0.0f64);
    let (mut best, mut best_t) = (f64::INFINITY, 0.0);
    for k in 0..SEARCH_SAMPLES {
        let c2 = c1 * c1 - s1 * s1;
        let s2 = 2.0 * s1 * c1;
        let s3 = s2 * c1 + c2 * s1;
        let x = [s1 + 2.0 * s2, c1 - 2.0 * c2 - CURVE_CENTER_Y, -s3];
        let d = crate::geometry::dist2(x, q);
        if d < best {
            best = d;
            best_t = k as f64 * dt;
        }
        (c1, s1) = (c1 * cd - s1 * sd, s1 * cd + c1 * sd);
    }
    let f = |t: f64| crate::geometry::dist2(curve(t), q);
    let (mut a, mut b) = (best_t - dt, best_t + dt);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..60 {
        if f1 <= f2 {
            (b, x2, f2) = (x2, x1, f1);
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            (a, x1, f1) = (x1, x2, f2);
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
    }
    best.min(f1).min(f2).sqrt() * scale_factor
}

/// Length of the trefoil centre line in trefoil units (composite Simpson rule, 4096 panels; the
/// integrand is smooth and periodic, so this is exact to rounding).
pub(super) fn curve_length() -> f64 {
    let n = 4096;
    let h = TAU / n as f64;
    (0..n).map(|i| speed(i as f64 * h)).sum::<f64>() * h
}

/// `n` parameters `t_i` equally spaced in arc length along the centre line (`t_0 = 0`).
pub(super) fn arc_length_parameters(n: usize) -> Vec<f64> {
    // Cumulative arc length on a fine grid (trapezoid; periodic integrand), then linear inversion.
    let m = 16 * n.max(64);
    let h = TAU / m as f64;
    let mut cum = Vec::with_capacity(m + 1);
    cum.push(0.0);
    let mut s = 0.0;
    for i in 0..m {
        s += 0.5 * h * (speed(i as f64 * h) + speed((i + 1) as f64 * h));
        cum.push(s);
    }
    let total = s;
    let mut out = Vec::with_capacity(n);
    let mut j = 0;
    for i in 0..n {
        let target = total * i as f64 / n as f64;
        while j + 1 < m && cum[j + 1] < target {
            j += 1;
        }
        let frac = (target - cum[j]) / (cum[j + 1] - cum[j]);
        out.push((j as f64 + frac) * h);
    }
    out
}

/// Largest curvature of the centre line in trefoil units, checked numerically in the tests.
#[cfg(test)]
fn max_curvature(samples: usize) -> f64 {
    (0..samples)
        .map(|i| frenet(TAU * i as f64 / samples as f64).curvature)
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::dot;

    #[test]
    fn closed_forms_match_the_derivatives() {
        for i in 0..200 {
            let t = TAU * i as f64 / 200.0;
            assert!((speed(t) - norm(d1(t))).abs() < 1e-12);
            let h = 1e-5;
            let fd = scale(sub(curve(t + h), curve(t - h)), 0.5 / h);
            assert!(norm(sub(fd, d1(t))) < 1e-8);
            let fd2 = scale(sub(d1(t + h), d1(t - h)), 0.5 / h);
            assert!(norm(sub(fd2, d2(t))) < 1e-7);
            let f = frenet(t);
            assert!(dot(f.normal, d1(t)).abs() < 1e-12);
        }
        assert!(max_curvature(20_000) < 0.78);
        assert!((curve_length() - 28.826).abs() < 1e-3);
    }

    #[test]
    fn strands_are_farther_apart_than_the_tube_diameter() {
        // Non-neighbouring points of the centre line (more than 0.8 apart in t) are ≥ 1.2 apart.
        let n = 1500;
        let pts: Vec<Point3> = (0..n).map(|i| curve(TAU * i as f64 / n as f64)).collect();
        for i in 0..n {
            for j in i + 1..n {
                let dt = TAU * (j - i) as f64 / n as f64;
                if dt.min(TAU - dt) > 0.8 {
                    assert!(crate::geometry::dist2(pts[i], pts[j]) > 1.2 * 1.2);
                }
            }
        }
    }

    #[test]
    fn arc_length_parameters_are_equally_spaced() {
        let ts = arc_length_parameters(500);
        let pts: Vec<Point3> = ts.iter().map(|&t| curve(t)).collect();
        let step = curve_length() / 500.0;
        for k in 0..500 {
            let d = norm(sub(pts[(k + 1) % 500], pts[k]));
            assert!((d - step).abs() < 1e-3 * step, "{d} vs {step}");
        }
    }
}
