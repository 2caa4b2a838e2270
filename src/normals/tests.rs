//! Estimated normals against the true normals of generated shapes, including thin and open ones.
//! The bounds are the ones docs/robustness.md summarises (section "Normals against the truth").

use crate::geometry::synthetic::{Coverage, Defects, Shape, apply_defects};
use crate::geometry::{Point3, PointCloud, dot, norm};
use crate::normals::{NormalParams, estimate_oriented_normals, reorient_normals};

/// `(flips, off)`: normals opposed to the truth, and lines more than 18° apart.
fn wrong(estimated: &[Point3], truth: &[Point3]) -> (usize, usize) {
    let cos18 = 18f64.to_radians().cos();
    let flips = estimated
        .iter()
        .zip(truth)
        .filter(|(a, b)| dot(**a, **b) < 0.0)
        .count();
    let off = estimated
        .iter()
        .zip(truth)
        .filter(|(a, b)| dot(**a, **b).abs() < cos18)
        .count();
    (flips, off)
}

fn check(name: &str, cloud: &PointCloud, max_flips: usize, max_off: usize) {
    let est = estimate_oriented_normals(&cloud.points, &NormalParams::default());
    let (flips, off) = wrong(&est, cloud.normals.as_ref().unwrap());
    let n = cloud.points.len();
    assert!(flips <= max_flips, "{name}: {flips} of {n} normals flipped");
    assert!(
        off <= max_off,
        "{name}: {off} of {n} normals more than 18° off"
    );
}

/// Scale about (0.5, 0.5, 0.5) by `s` per axis; normals by the inverse transpose.
fn stretched(mut cloud: PointCloud, s: Point3) -> PointCloud {
    for p in &mut cloud.points {
        *p = std::array::from_fn(|k| 0.5 + (p[k] - 0.5) * s[k]);
    }
    for n in cloud.normals.as_mut().unwrap() {
        let m: Point3 = std::array::from_fn(|k| n[k] / s[k]);
        *n = m.map(|v| v / norm(m));
    }
    cloud
}

#[test]
fn closed_shapes_get_outward_normals() {
    for (name, n) in [
        ("sphere", 4000),
        ("torus", 8000),
        ("two-spheres", 6000),
        ("knot", 8000),
    ] {
        let cloud = Shape::by_name(name).unwrap().sample(n, 9);
        check(name, &cloud, 0, n / 100);
    }
}

#[test]
fn thin_parts_and_near_touching_sheets_keep_their_orientation() {
    let thin_torus = Shape::Torus {
        center: [0.5; 3],
        major: 0.35,
        minor: 0.02,
    };
    check("thin torus", &thin_torus.sample(5000, 6), 0, 50);
    let touching = Shape::TwoSpheres {
        center: [0.5; 3],
        radius: 0.2,
        gap: 0.005,
    };
    // The few flips are a 14-point patch at the contact.
    check(
        "two spheres 0.005 apart",
        &touching.sample(8000, 7),
        10,
        100,
    );
    let sphere = Shape::by_name("sphere").unwrap();
    let pancake = stretched(sphere.sample(10000, 8), [1.0, 1.0, 0.05]);
    // Known weak case: the rim is thinner than the point spacing, so PCA lines are wrong there
    // (2849 off by > 18°) and 609 normals come out flipped (4805 with MST propagation).
    check("pancake 1:20", &pancake, 650, 2900);
}

#[test]
fn a_range_image_is_oriented_towards_the_scanner() {
    let mut cloud = Shape::by_name("torus").unwrap().sample(10000, 11);
    let view = Coverage::RangeImage {
        view: [0.3, 0.2, 1.0],
    };
    let d = Defects {
        coverage: view,
        ..Defects::default()
    };
    apply_defects(&mut cloud, &d, 3).unwrap();
    check("torus range image", &cloud, 0, 50);
}

#[test]
fn reorienting_randomly_flipped_normals_restores_them() {
    let cloud = Shape::by_name("knot").unwrap().sample(6000, 2);
    let truth = cloud.normals.as_ref().unwrap();
    let scrambled: Vec<Point3> = truth
        .iter()
        .enumerate()
        .map(|(i, n)| if i % 3 == 0 { n.map(|v| -v) } else { *n })
        .collect();
    let (fixed, flipped) = reorient_normals(&cloud.points, &scrambled, &NormalParams::default());
    assert_eq!(wrong(&fixed, truth).0, 0);
    assert_eq!(flipped, 2000);
}

/// Points on the two faces of a plate thinner than a 12-neighbourhood (`z = 0.5 ± t/2`, the top
/// face sampled twice as densely, so one face outnumbers the other in most neighbourhoods).
fn two_faced_plate(thickness: f64, noise: f64) -> Vec<Point3> {
    let mut rng = crate::geometry::synthetic::SplitMix64(41);
    let mut points = Vec::new();
    for (count, z) in [(4000, 0.5 + thickness / 2.0), (2000, 0.5 - thickness / 2.0)] {
        for _ in 0..count {
            let (x, y) = (0.2 + 0.6 * rng.next_f64(), 0.2 + 0.6 * rng.next_f64());
            points.push([x, y, z + noise * rng.next_gaussian()]);
        }
    }
    points
}

/// Lines more than 18° off `z`, for plain 12-neighbour PCA and for the shipped estimate.
fn plate_lines_off(points: &[Point3]) -> (usize, usize) {
    let cos18 = 18f64.to_radians().cos();
    let (lines, neighbours) = crate::normals::estimate_normals(points, 12);
    let off = |n: &Point3| n[2].abs() < cos18;
    let plain = points
        .iter()
        .zip(&neighbours)
        .filter(|(p, list)| {
            let mut local = vec![**p];
            local.extend(list.iter().map(|&j| points[j as usize]));
            off(&crate::geometry::pca::pca(&local).axes[2])
        })
        .count();
    (plain, lines.iter().filter(|n| off(n)).count())
}

#[test]
fn a_plate_thinner_than_the_neighbourhood_gets_each_face_its_own_plane() {
    // 12-neighbour radius ≈ 0.015–0.017 here (measured), 1.5 times the thickness.
    let (plain, shipped) = plate_lines_off(&two_faced_plate(0.01, 0.0));
    // Measured: plain 3003, shipped 339 (at the plate's border and where a neighbourhood holds
    // fewer than 4 points of the point's own face).
    assert!(plain > 2500, "the case is hard for plain PCA: {plain}");
    assert!(shipped < 400, "{shipped} of 6000 lines more than 18° off");
    // A single noisy sheet has no second sheet: it keeps (nearly) its PCA planes. A trial plane
    // may split off a few tail points, so a few lines move.
    let sheet: Vec<Point3> = two_faced_plate(0.0, 0.002);
    let (plain, shipped) = plate_lines_off(&sheet);
    assert!(
        shipped <= plain,
        "noisy sheet: {shipped} lines off, plain PCA {plain}"
    );
    let (lines, neighbours) = crate::normals::estimate_normals(&sheet, 12);
    let cos10 = 10f64.to_radians().cos();
    let (mut moved, mut far) = (0, 0);
    for ((p, list), n) in sheet.iter().zip(&neighbours).zip(&lines) {
        let mut local = vec![*p];
        local.extend(list.iter().map(|&j| sheet[j as usize]));
        let plain = crate::geometry::pca::pca(&local).axes[2];
        far += usize::from(dot(plain, *n).abs() < cos10);
        moved += usize::from(dot(plain, *n).abs() < 1.0 - 1e-12);
        let _ = p;
    }
    // Measured: 8 moved, 2 of them by more than 10°; 85 lines more than 18° off either way.
    assert!(
        moved < 30 && far <= 5,
        "{moved} lines moved, {far} by > 10°"
    );
}

/// The height field `z = 0.15 sin 2x cos 3y` and its upward unit normal at `(x, y)`.
fn wave(x: f64, y: f64) -> (f64, Point3) {
    let (dx, dy) = (
        0.3 * (2.0 * x).cos() * (3.0 * y).cos(),
        -0.45 * (2.0 * x).sin() * (3.0 * y).sin(),
    );
    let l = (dx * dx + dy * dy + 1.0).sqrt();
    (
        0.15 * (2.0 * x).sin() * (3.0 * y).cos(),
        [-dx / l, -dy / l, 1.0 / l],
    )
}

/// A noisy, nearly flat open sheet (a terrain tile or a wall: 120k points, σ = 0.3 spacing)
/// encloses nothing: its winding numbers are noise around 0, which must not flip patches of it
/// inward (it did: thousands of points in small patches at 10⁶ points, each a pinhole in the
/// surface). Its estimated normals all agree with one of the two sides.
#[test]
fn a_noisy_flat_sheet_is_oriented_one_way() {
    let n = 120_000;
    let mut rng = crate::geometry::synthetic::SplitMix64(5);
    let spacing = (12.0 / n as f64).sqrt();
    let (mut points, mut truth) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        let (x, y) = (4.0 * rng.next_f64(), 3.0 * rng.next_f64());
        let (z, normal) = wave(x, y);
        points.push([x, y, z + 0.3 * spacing * rng.next_gaussian()]);
        truth.push(normal);
    }
    let est = estimate_oriented_normals(&points, &NormalParams::default());
    let (flips, _) = wrong(&est, &truth);
    let minority = flips.min(n - flips);
    assert!(
        minority <= n / 2000,
        "{minority} of {n} normals against the rest"
    );
}

/// A height field sampled on scan lines (a LiDAR's or a profile scanner's: lines 0.03 apart, a
/// point every 0.004 along them, noise 0.002 across and 0.001 in height), `x y z` only: the 12
/// nearest points of a point lie on its own line, whose plane is undetermined; the neighbourhood
/// is widened until it spans the surface.
/// Before: 12.7 % of the normals more than 18° off.
#[test]
fn normals_on_scan_lines_span_the_surface() {
    let mut rng = crate::geometry::synthetic::SplitMix64(7);
    let (mut points, mut truth) = (Vec::new(), Vec::new());
    for i in 0..40 {
        for j in 0..500 {
            let x = 0.03 * i as f64 + 0.002 * rng.next_gaussian();
            let y = 0.004 * j as f64;
            let (z, normal) = wave(x, y);
            points.push([x, y, z + 0.001 * rng.next_gaussian()]);
            truth.push(normal);
        }
    }
    let n = points.len();
    let est = estimate_oriented_normals(&points, &NormalParams::default());
    let (flips, off) = wrong(&est, &truth);
    assert!(flips.min(n - flips) <= n / 1000, "{flips} of {n} flipped");
    assert!(off <= n / 100, "{off} of {n} normals more than 18° off");
}
