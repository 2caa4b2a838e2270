//! The large-scan machinery on small inputs, against analytic truth and against the single global
//! system: partition-of-unity blocks, multi-level fits, conjugate gradients.

use crate::common;

use rbfsurf::geometry::PointCloud;
use rbfsurf::geometry::synthetic::Shape;
use rbfsurf::linalg::SolverKind;
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::fit_field;
use rbfsurf::progress::NoProgress;
use rbfsurf::rbf::Blocks;
use rbfsurf::reconstruct;

fn params(blocks: Blocks, levels: usize) -> ReconParams {
    // Every grid triangle, so two fits of the same field can be compared mesh to mesh.
    ReconParams {
        blocks,
        levels,
        chord_error: rbfsurf::params::ChordTolerance::Off,
        ..Default::default()
    }
}

#[test]
fn blocks_interpolate_and_give_the_topology_and_surface_of_one_global_system() {
    let shape = Shape::by_name("torus").unwrap();
    let cloud = shape.sample(12_000, 21);
    let global = reconstruct(&cloud, &params(Blocks::None, 1), &NoProgress).unwrap();
    let split = reconstruct(&cloud, &params(Blocks::MaxPoints(2000), 1), &NoProgress).unwrap();
    assert!(
        split.report.matrix.blocks >= 8,
        "{:?}",
        split.report.matrix.blocks
    );
    assert!(split.report.matrix.n > 12_000, "overlaps duplicate points");
    for rec in [&global, &split] {
        let m = &rec.report.mesh;
        assert!(m.watertight && m.manifold && m.components == 1, "{m:?}");
        assert_eq!(m.genus, Some(1));
        assert!(rec.report.residual.max < 1e-8, "{:?}", rec.report.residual);
        let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
        assert!(err < 0.01, "max vertex error {err}");
    }
    // The two surfaces against each other, not only each against the truth.
    let d = rbfsurf::mesh::compare::compare(
        &split.mesh,
        rbfsurf::mesh::compare::Reference::Mesh(&global.mesh),
        &Default::default(),
    )
    .unwrap();
    // Measured: Chamfer 3.0e-8, Hausdorff 1.8e-6 of the diagonal.
    assert!(d.chamfer_rel < 1e-6 && d.hausdorff_rel < 1e-4, "{d:?}");
}

#[test]
fn the_blended_field_is_continuous_and_its_gradient_matches_finite_differences() {
    let shape = Shape::by_name("sphere").unwrap();
    let cloud = shape.sample(6000, 22);
    let p = params(Blocks::MaxPoints(1000), 2);
    let mut timings = Default::default();
    let fit = fit_field(&cloud, &p, &NoProgress, &mut timings).unwrap();
    assert!(fit.matrix.blocks > 1);
    // Walk a line through block overlaps: no step changes the field by more than the step length
    // times 1.5 × the larger gradient norm at its two ends (the mean value theorem with a margin
    // for the gradient's variation over one step of 3e-4); a seam would show as a jump.
    let (a, b): ([f64; 3], [f64; 3]) = ([0.05, 0.1, 0.2], [0.95, 0.85, 0.8]);
    let steps = 4000;
    let step = (0..3).map(|k| (b[k] - a[k]).powi(2)).sum::<f64>().sqrt() / steps as f64;
    let slope = |x: &[f64; 3]| {
        let g = fit.field.gradient(x);
        (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt()
    };
    let (mut prev, mut prev_slope) = (fit.field.value(&a), slope(&a));
    let mut worst: f64 = 0.0;
    let (r, mut checked) = (fit.support_radius, 0);
    for s in 1..=steps {
        let t = s as f64 / steps as f64;
        let x = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
        let (v, sl) = (fit.field.value(&x), slope(&x));
        let bound = 1.5 * step * prev_slope.max(sl) + 1e-12;
        worst = worst.max((v - prev).abs() / bound);
        assert!(
            (v - prev).abs() <= bound,
            "jump {} > {bound} at t = {t}",
            v - prev
        );
        (prev, prev_slope) = (v, sl);
        // The analytic gradient is exact where the field is smooth: within the data band, where
        // the local carrier's radius is the fixed support R (at least FAR_NEIGHBOURS points within
        // R). Off the data the carrier widens to its K nearest planes: continuous (checked above)
        // but only piecewise smooth (kinks where the K-th neighbour changes).
        let in_band = fit
            .points
            .iter()
            .filter(|p| (0..3).map(|k| (p[k] - x[k]).powi(2)).sum::<f64>() <= r * r)
            .count()
            >= rbfsurf::rbf::carrier::FAR_NEIGHBOURS;
        if s % 23 == 0 && in_band {
            checked += 1;
            let g = fit.field.gradient(&x);
            let h = 1e-6;
            for k in 0..3 {
                let (mut u, mut d) = (x, x);
                u[k] += h;
                d[k] -= h;
                let fd = (fit.field.value(&u) - fit.field.value(&d)) / (2.0 * h);
                assert!(
                    (fd - g[k]).abs() < 1e-4 * (1.0 + g[k].abs()),
                    "{fd} vs {}",
                    g[k]
                );
            }
        }
    }
    assert!(worst > 0.0, "the walk measured nothing");
    assert!(
        checked >= 10,
        "only {checked} gradient checks in the data band"
    );
}

#[test]
fn multi_level_fits_halve_the_support_and_stay_on_the_surface() {
    let shape = Shape::by_name("two-spheres").unwrap();
    let cloud = shape.sample(8000, 23);
    let rec = reconstruct(&cloud, &params(Blocks::None, 3), &NoProgress).unwrap();
    let levels = &rec.report.matrix.levels;
    assert_eq!(levels.len(), 3);
    for w in levels.windows(2) {
        assert!((w[0].support - 2.0 * w[1].support).abs() < 1e-12);
        assert!(w[0].n < w[1].n);
    }
    // Each level leaves less to interpolate than the one before.
    assert!(levels[2].rhs_rms < levels[0].rhs_rms, "{levels:?}");
    let m = &rec.report.mesh;
    assert!(
        m.watertight && m.components == 2 && m.genus == Some(0),
        "{m:?}"
    );
    assert!(rec.report.residual.rms < 1e-4, "{:?}", rec.report.residual);
    let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
    assert!(err < 0.01, "max vertex error {err}");
}

#[test]
fn a_hole_closes_with_boundary_closed_and_the_data_side_stays_exact() {
    let shape = Shape::by_name("sphere").unwrap();
    let full = shape.sample(6000, 24);
    let (points, normals): (Vec<_>, Vec<_>) = full
        .points
        .iter()
        .zip(full.normals.as_ref().unwrap())
        .filter(|(p, _)| p[2] < 0.82)
        .map(|(p, n)| (*p, *n))
        .unzip();
    let cloud = PointCloud {
        points,
        normals: Some(normals),
        ..Default::default()
    };
    let rec = reconstruct(
        &cloud,
        &ReconParams {
            boundary: rbfsurf::params::Boundary::Closed,
            ..params(Blocks::None, 3)
        },
        &NoProgress,
    )
    .unwrap();
    let m = &rec.report.mesh;
    assert!(
        m.watertight && m.components == 1 && m.genus == Some(0),
        "{m:?}"
    );
    // Over the hole the surface follows the rim's tangent planes (a cone, apex ~0.1 above the
    // sphere's pole); on the data side it stays on the sphere.
    let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
    assert!(err < 0.15, "max vertex error {err}");
    let below = rbfsurf::geometry::TriMesh {
        triangles: Vec::new(),
        normals: Vec::new(),
        vertices: rec
            .mesh
            .vertices
            .iter()
            .filter(|p| p[2] < 0.78)
            .copied()
            .collect(),
        colors: Vec::new(),
    };
    let err = common::max_vertex_error(&below, |p| shape.signed_distance(p));
    assert!(err < 0.01, "max vertex error on the data side {err}");
}

#[test]
fn conjugate_gradients_give_the_direct_solution_on_the_bunny_scan() {
    let cloud = rbfsurf::io::read_point_cloud(
        std::path::Path::new("data/bunny_cgal_10k.ply"),
        &Default::default(),
    )
    .unwrap();
    let direct = ReconParams {
        solver: SolverKind::Sparse,
        resolution: Some(64),
        ..params(Blocks::None, 1)
    };
    let cg = ReconParams {
        solver: SolverKind::Cg,
        ..direct.clone()
    };
    let a = reconstruct(&cloud, &direct, &NoProgress).unwrap();
    let b = reconstruct(&cloud, &cg, &NoProgress).unwrap();
    assert_eq!(b.report.matrix.solver_used.names(), ["cg"]);
    assert_eq!(b.report.matrix.factor_values, 0);
    assert!(b.report.matrix.levels[0].iterations.unwrap() > 10);
    assert!(b.report.residual.max < 1e-7, "{:?}", b.report.residual);
    let d = rbfsurf::mesh::compare::compare(
        &b.mesh,
        rbfsurf::mesh::compare::Reference::Mesh(&a.mesh),
        &Default::default(),
    )
    .unwrap();
    // Same surface: a few grid corners with |f| ~ 1e-12 may switch sign (a vertex moves within
    // its cell, 1/64 of the box ≈ 0.01 of the diagonal); everywhere else they agree to 1e-6.
    assert!(d.chamfer_rel < 1e-6 && d.hausdorff_rel < 0.01, "{d:?}");
}

#[test]
fn inconsistently_oriented_normals_are_reoriented_and_counted() {
    let shape = Shape::by_name("torus").unwrap();
    let mut cloud = shape.sample(8000, 25);
    let normals = cloud.normals.as_mut().unwrap();
    let mut rng = rbfsurf::geometry::synthetic::SplitMix64(9);
    let mut flipped = 0;
    for n in normals.iter_mut() {
        if rng.next_f64() < 0.3 {
            *n = [-n[0], -n[1], -n[2]];
            flipped += 1;
        }
    }
    let rec = reconstruct(&cloud, &params(Blocks::None, 1), &NoProgress).unwrap();
    assert_eq!(rec.report.params.normals, "input-reoriented");
    let r = rec.report.params.normals_reoriented;
    // Either the flipped ones were turned back, or (whole orientation reversed) the others were.
    assert!(r == flipped || r == 8000 - flipped, "{r} vs {flipped}");
    let m = &rec.report.mesh;
    assert!(
        m.watertight && m.components == 1 && m.genus == Some(1),
        "{m:?}"
    );
    let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
    assert!(err < 0.01, "max vertex error {err}");
}

#[test]
fn a_cloud_of_pure_noise_is_reported_not_meshed_silently() {
    let mut rng = rbfsurf::geometry::synthetic::SplitMix64(10);
    let points = (0..4000)
        .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
        .collect();
    let cloud = PointCloud {
        points,
        normals: None,
        ..Default::default()
    };
    let r = reconstruct(&cloud, &params(Blocks::None, 1), &NoProgress);
    match r {
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains("surface"), "{msg}");
        }
        Ok(rec) => panic!("meshed noise: {:?}", rec.report.mesh),
    }
}

#[test]
fn min_component_drops_floaters_and_keeps_equal_parts() {
    let shape = Shape::by_name("two-spheres").unwrap();
    let mut cloud = shape.sample(6000, 26);
    // Three tiny spheres (radius 0.02) of 80 points each, away from the two big ones.
    for (k, c) in [[0.5, 0.5, 0.9], [0.1, 0.9, 0.5], [0.9, 0.1, 0.1]]
        .iter()
        .enumerate()
    {
        let tiny = Shape::Sphere {
            center: *c,
            radius: 0.02,
        }
        .sample(80, 30 + k as u64);
        cloud.points.extend(tiny.points);
        cloud
            .normals
            .as_mut()
            .unwrap()
            .extend(tiny.normals.unwrap());
    }
    let keep = reconstruct(&cloud, &params(Blocks::None, 1), &NoProgress).unwrap();
    assert_eq!(keep.report.mesh.components, 5, "{:?}", keep.report.mesh);
    let p = ReconParams {
        min_component: 0.05,
        ..params(Blocks::None, 1)
    };
    let drop = reconstruct(&cloud, &p, &NoProgress).unwrap();
    let m = &drop.report.mesh;
    assert!(
        m.components == 2 && m.watertight && m.genus == Some(0),
        "{m:?}"
    );
    assert_eq!(drop.report.polygonize.small_components_removed, 3);
    assert!(drop.report.polygonize.small_component_triangles > 0);
}
