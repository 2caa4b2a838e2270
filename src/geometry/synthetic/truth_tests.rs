//! Tests of the truth meshes (topology, accuracy, convergence, area and volume) and of the
//! area-uniformity of the samplers, measured against the truth meshes.

use super::super::{SHAPE_NAMES, bumpy};
use super::*;
use crate::geometry::{add, dist2, norm, scale, sub};
use crate::mesh::topology::{analyze, area, signed_volume};

fn centroid(m: &TriMesh, t: &[u32; 3]) -> Point3 {
    let [a, b, c] = t.map(|v| m.vertices[v as usize]);
    scale(add(add(a, b), c), 1.0 / 3.0)
}

fn longest_edge(m: &TriMesh) -> f64 {
    m.triangles
        .iter()
        .flat_map(|t| {
            (0..3).map(move |k| {
                dist2(
                    m.vertices[t[k] as usize],
                    m.vertices[t[(k + 1) % 3] as usize],
                )
            })
        })
        .fold(0.0, f64::max)
        .sqrt()
}

/// Largest |signed distance| of the triangle centroids.
fn max_centroid_error(s: &Shape, m: &TriMesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| s.signed_distance(&centroid(m, t)).abs())
        .fold(0.0, f64::max)
}

/// Largest principal curvature of the shapes with an exact signed distance.
fn max_curvature(s: &Shape) -> f64 {
    match *s {
        Shape::Sphere { radius, .. } | Shape::TwoSpheres { radius, .. } => 1.0 / radius,
        Shape::Torus { minor, .. } => 1.0 / minor,
        Shape::Knot { scale, tube, .. } => {
            let k = 0.78 / scale;
            (1.0 / tube).max(k / (1.0 - k * tube))
        }
        Shape::BumpySphere { .. } => f64::NAN,
    }
}

#[test]
fn truth_meshes_are_closed_oriented_outward_with_the_right_genus() {
    for name in SHAPE_NAMES {
        let s = Shape::by_name(name).unwrap();
        let m = s.truth_mesh(96);
        assert_eq!(m.triangles.len(), s.truth_triangles(96), "{name}");
        let t = analyze(&m);
        assert!(t.watertight && t.manifold && t.oriented, "{name}: {t:?}");
        assert_eq!(t.components, s.components(), "{name}");
        assert_eq!(t.genus, Some(s.genus()), "{name}");
        assert_eq!(t.degenerate_triangles, 0, "{name}");
        assert!(signed_volume(&m) > 0.0, "{name}: inward winding");
        for (p, n) in m.vertices.iter().zip(&m.normals) {
            match s {
                Shape::BumpySphere {
                    center,
                    radius,
                    amplitude,
                } => assert!(bumpy::implicit(p, center, radius, amplitude).0.abs() < 1e-14),
                _ => assert!(s.signed_distance(p).abs() < 1e-12, "{name}"),
            }
            assert!((norm(*n) - 1.0).abs() < 1e-12);
            assert!(s.signed_distance(&add(*p, scale(*n, 1e-4))) > 0.0, "{name}");
            assert!(s.signed_distance(&sub(*p, scale(*n, 1e-4))) < 0.0, "{name}");
        }
    }
}

#[test]
fn truth_mesh_centroids_are_within_h_squared_of_the_surface_and_converge_quadratically() {
    for name in ["sphere", "torus", "two-spheres", "knot"] {
        let s = Shape::by_name(name).unwrap();
        let (coarse, fine) = (s.truth_mesh(160), s.truth_mesh(320));
        let (ec, ef) = (
            max_centroid_error(&s, &coarse),
            max_centroid_error(&s, &fine),
        );
        let h = longest_edge(&fine);
        let bound = 0.5 * max_curvature(&s) * h * h;
        assert!(
            ef <= bound,
            "{name}: centroid error {ef} > {bound} (h = {h})"
        );
        let ratio = ec / ef;
        assert!((3.0..5.0).contains(&ratio), "{name}: error ratio {ratio}");
    }
}

#[test]
fn truth_mesh_area_and_volume_match_the_closed_forms() {
    let cases: Vec<(&str, f64, f64)> = SHAPE_NAMES
        .iter()
        .filter_map(|&name| {
            let (a, v) = match Shape::by_name(name)? {
                Shape::Sphere { radius: r, .. } => (4.0 * PI * r * r, 4.0 / 3.0 * PI * r.powi(3)),
                Shape::TwoSpheres { radius: r, .. } => {
                    (8.0 * PI * r * r, 8.0 / 3.0 * PI * r.powi(3))
                }
                Shape::Torus { major, minor, .. } => (
                    4.0 * PI * PI * major * minor,
                    2.0 * PI * PI * major * minor * minor,
                ),
                // Tube formulas (Pappus–Guldin / Weyl), exact for a tube without self-intersection.
                Shape::Knot { scale, tube, .. } => {
                    let l = scale * knot::curve_length();
                    (TAU * tube * l, PI * tube * tube * l)
                }
                Shape::BumpySphere { .. } => return None,
            };
            Some((name, a, v))
        })
        .collect();
    for (name, a, v) in cases {
        let s = Shape::by_name(name).unwrap();
        let m = s.truth_mesh(320);
        // An inscribed n-gon loses ≈ (π/n)²/6 of its perimeter and ≈ 2(π/n)²/3 of its area.
        let tol = (PI / s.truth_grid(320).1 as f64).powi(2);
        let (ma, mv) = (area(&m), signed_volume(&m));
        assert!((ma / a - 1.0).abs() < tol, "{name}: area {ma} vs {a}");
        assert!((mv / v - 1.0).abs() < tol, "{name}: volume {mv} vs {v}");
        assert!(ma < a && mv < v, "{name}: an inscribed mesh is smaller");
    }
}

/// Fraction of the truth mesh's area (by triangle centroid) and of `n` samples inside `region`.
fn area_fractions(s: &Shape, region: impl Fn(&Point3) -> bool, n: usize) -> (f64, f64) {
    let m = s.truth_mesh(400);
    let (mut inside, mut total) = (0.0, 0.0);
    for t in &m.triangles {
        let [a, b, c] = t.map(|v| m.vertices[v as usize]);
        let ar = 0.5 * norm(crate::geometry::cross(sub(b, a), sub(c, a)));
        total += ar;
        if region(&centroid(&m, t)) {
            inside += ar;
        }
    }
    let cloud = s.sample(n, 11);
    let hits = cloud.points.iter().filter(|p| region(p)).count();
    (inside / total, hits as f64 / n as f64)
}

#[test]
fn samples_are_uniform_by_area() {
    // Regions where the area element varies: the knot's inner bends and fast stretches, the bumps.
    type Region = Box<dyn Fn(&Point3) -> bool>;
    let cases: Vec<(&str, Region)> = vec![
        ("knot", Box::new(|p: &Point3| p[0] > 0.6)),
        ("knot", Box::new(|p: &Point3| p[2] > 0.52)),
        (
            "knot",
            Box::new(|p: &Point3| dist2(*p, [0.5, 0.43, p[2]]) < 0.2 * 0.2),
        ),
        ("bumpy-sphere", Box::new(|p: &Point3| p[2] > 0.75)),
        ("bumpy-sphere", Box::new(|p: &Point3| p[0] > 0.7)),
        (
            "torus",
            Box::new(|p: &Point3| dist2(*p, [0.5, 0.5, p[2]]) < 0.3 * 0.3),
        ),
    ];
    for (name, region) in cases {
        let (want, got) = area_fractions(&Shape::by_name(name).unwrap(), region, 20_000);
        // Binomial standard error at 20,000 samples is ≤ 0.0036.
        assert!(
            (want - got).abs() < 0.012,
            "{name}: area fraction {want}, samples {got}"
        );
    }
}
