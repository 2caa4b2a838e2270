//! Tests of the carriers.
use super::*;

fn sphere_points(n: usize, c: Point3, r: f64) -> (Vec<Point3>, Vec<Point3>) {
    (0..n)
        .map(|i| {
            let u = crate::geometry::fibonacci_direction(i, n);
            ([c[0] + r * u[0], c[1] + r * u[1], c[2] + r * u[2]], u)
        })
        .unzip()
}

fn local(p: &[Point3], n: &[Point3], r: f64) -> LocalCarrier {
    local_fit(p, n, r, LocalFit::Plane)
}

fn local_fit(p: &[Point3], n: &[Point3], r: f64, fit: LocalFit) -> LocalCarrier {
    let index: Arc<dyn SpatialIndex + Send> =
        Arc::from(crate::spatial::build_index(p, crate::spatial::IndexKind::KdTree, 16).unwrap());
    LocalCarrier::new(p, n, r, index, fit).unwrap()
}

#[test]
fn the_decided_far_field_is_the_blend_it_replaces() {
    let (p, n) = sphere_points(2000, [0.5, 0.5, 0.5], 0.25);
    let c = local(&p, &n, 0.05);
    let (mut decided, mut undecided) = (0, 0);
    for i in 0..20 * 20 * 20 {
        let x = [i % 20, (i / 20) % 20, i / 400].map(|k| (k as f64 + 0.37) / 20.0);
        let full = c.nearest_planes_with_far_field::<true>(&x);
        let Some(far) = c.decided_far_field::<true>(&x) else {
            undecided += 1;
            continue;
        };
        decided += 1;
        assert_eq!(far.0.to_bits(), full.0.to_bits(), "value at {x:?}");
        for k in 0..3 {
            assert!((far.1[k] - full.1[k]).abs() <= 1e-12, "{far:?} vs {full:?}");
        }
        assert_eq!(c.value_gradient_with(&x, &[]).0.to_bits(), far.0.to_bits());
    }
    // Inside the ball away from the shell and far outside: decided; near the shell: not.
    assert!(decided > 4000 && undecided > 500, "{decided} / {undecided}");
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
        Carrier::Local(local_fit(&p, &n, 0.08, LocalFit::Quadric)),
        // An open cap: beside it the winding number is undecided (the far field's confidence
        // varies), below its rim the planes hand over to the far field.
        {
            let keep: Vec<usize> = (0..p.len()).filter(|&i| p[i][1] > 0.45).collect();
            let hp: Vec<Point3> = keep.iter().map(|&i| p[i]).collect();
            let hn: Vec<Point3> = keep.iter().map(|&i| n[i]).collect();
            Carrier::Local(local(&hp, &hn, 0.08))
        },
        // The same cap with quadrics: at its rim their fits are one-sided, and between R
        // and 2R from the points the taper hands them over to the planes.
        {
            let keep: Vec<usize> = (0..p.len()).filter(|&i| p[i][1] > 0.45).collect();
            let hp: Vec<Point3> = keep.iter().map(|&i| p[i]).collect();
            let hn: Vec<Point3> = keep.iter().map(|&i| n[i]).collect();
            Carrier::Local(local_fit(&hp, &hn, 0.08, LocalFit::Quadric))
        },
    ];
    for c in &carriers {
        for x in [
            [0.71, 0.52, 0.48],
            [0.2, 0.33, 0.61],
            [0.5, 0.9, 0.4],
            [0.5, 0.3, 0.45],
            [0.93, 0.41, 0.52],
        ] {
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

#[test]
fn quadrics_follow_a_sphere_where_planes_cut_it() {
    // On a sphere of radius 0.3 the planes' blend at a data point is the mean drop of the
    // neighbours' tangent planes, about −d²/(2ρ): the spline has to make that up. The
    // quadrics fit the curvature, so their blend nearly vanishes on the data, and at 0.3 R
    // off the surface it is the distance (measured: planes 8.4e-4 / 8.0e-4, quadrics 2.7e-6 /
    // 4.8e-5 on the data / at 0.3 R).
    let (p, n) = sphere_points(3000, [0.5; 3], 0.3);
    let r = 0.06;
    let planes = local_fit(&p, &n, r, LocalFit::Plane);
    let quads = local_fit(&p, &n, r, LocalFit::Quadric);
    assert_eq!(
        (planes.fit(), quads.fit()),
        (LocalFit::Plane, LocalFit::Quadric)
    );
    let worst = |c: &LocalCarrier, off: f64| {
        (0..p.len())
            .step_by(7)
            .map(|i| {
                let x = [0, 1, 2].map(|k| p[i][k] + off * n[i][k]);
                (c.value(&x) - off).abs()
            })
            .fold(0.0f64, f64::max)
    };
    for off in [0.0, 0.3 * r, -0.3 * r] {
        let (wp, wq) = (worst(&planes, off), worst(&quads, off));
        assert!(wp > 1e-4, "planes at {off}: {wp}");
        assert!(wq < 0.1 * wp, "quadrics at {off}: {wq} vs planes {wp}");
    }
}

#[test]
fn a_quadric_leaves_out_the_far_side_of_a_thin_slab() {
    // Two parallel sheets 0.4 R apart with opposite normals: a quadric fitted over all
    // neighbours would bend towards the other sheet; fitted over the agreeing ones it is the
    // flat sheet, so the carrier is the planes' exactly up to rounding.
    let (mut p, mut n) = (Vec::new(), Vec::new());
    let r = 0.1;
    for i in 0..40 {
        for j in 0..40 {
            let (x, y) = (0.3 + i as f64 * 0.01, 0.3 + j as f64 * 0.01);
            p.push([x, y, 0.5]);
            n.push([0.0, 0.0, 1.0]);
            p.push([x + 0.005, y + 0.005, 0.5 - 0.4 * r]);
            n.push([0.0, 0.0, -1.0]);
        }
    }
    let planes = local_fit(&p, &n, r, LocalFit::Plane);
    let quads = local_fit(&p, &n, r, LocalFit::Quadric);
    for x in [
        [0.5, 0.5, 0.5 - 0.2 * r],
        [0.45, 0.52, 0.5 + 0.3 * r],
        [0.5, 0.5, 0.6],
    ] {
        let (a, b) = (planes.value(&x), quads.value(&x));
        assert!((a - b).abs() < 1e-12, "{x:?}: planes {a} vs quadrics {b}");
    }
}

#[test]
fn a_flipped_quadric_carrier_loads_bit_for_bit_from_its_parts() {
    let (p, n) = sphere_points(1500, [0.5; 3], 0.3);
    let mut c = local_fit(&p, &n, 0.07, LocalFit::Quadric);
    c.flip_normals();
    let index: Arc<dyn SpatialIndex + Send> =
        Arc::from(crate::spatial::build_index(&p, crate::spatial::IndexKind::KdTree, 16).unwrap());
    let loaded = LocalCarrier::from_parts(
        c.points().to_vec(),
        c.normals().to_vec(),
        c.radius(),
        index,
        c.fit(),
    )
    .unwrap();
    for x in [
        [0.71, 0.52, 0.48],
        [0.5, 0.81, 0.5],
        [0.2, 0.5, 0.55],
        [0.5, 0.5, 0.5],
    ] {
        let (a, b) = (c.value_gradient(&x), loaded.value_gradient(&x));
        assert_eq!(a.0.to_bits(), b.0.to_bits(), "{x:?}");
        assert_eq!(a.1.map(f64::to_bits), b.1.map(f64::to_bits), "{x:?}");
        assert!(a.0 != 0.0);
    }
}

#[test]
fn wide_quadrics_average_the_noise_of_a_sphere() {
    // A sphere of radius 0.3 whose points are moved along the normal by uniform noise of
    // ±0.4 of the spacing (σ ≈ 0.23 spacing) and whose normals are tilted by up to 0.1 rad:
    // on the true sphere the planes' blend keeps their curvature drop, the quadrics over R
    // follow the noise, and the quadrics over 2R average it (measured RMS: planes 1.10e-3,
    // quadrics 1.18e-3, wide 6.99e-4; the noise itself ≈ 3.2e-3).
    let (p0, n) = sphere_points(6000, [0.5; 3], 0.3);
    let spacing = (4.0 * std::f64::consts::PI * 0.09 / 6000.0f64).sqrt();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let p: Vec<Point3> = (p0.iter().zip(&n))
        .map(|(q, m)| {
            let e = 0.8 * spacing * rnd();
            [0, 1, 2].map(|k| q[k] + e * m[k])
        })
        .collect();
    let nn: Vec<Point3> = n
        .iter()
        .map(|m| crate::geometry::normalized([0, 1, 2].map(|k| m[k] + 0.1 * rnd())).unwrap())
        .collect();
    let r = 0.06;
    let rms = |fit| {
        let c = local_fit(&p, &nn, r, fit);
        assert_eq!(c.fit(), fit);
        let s: f64 = p0.iter().step_by(5).map(|x| c.value(x).powi(2)).sum();
        (s / p0.iter().step_by(5).count() as f64).sqrt()
    };
    let (planes, quads, wide) = (
        rms(LocalFit::Plane),
        rms(LocalFit::Quadric),
        rms(LocalFit::WideQuadric),
    );
    println!(
        "RMS carrier on the true sphere: planes {planes:.2e}, quadrics {quads:.2e}, wide {wide:.2e}"
    );
    assert!(
        wide < 0.7 * planes.min(quads),
        "planes {planes}, quadrics {quads}, wide {wide}"
    );
}
