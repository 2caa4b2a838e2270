//! End-to-end reconstruction on synthetic shapes with analytic truth and on the shipped real data.

use crate::common;

use rbfsurf::geometry::PointCloud;
use rbfsurf::geometry::synthetic::Shape;
use rbfsurf::linalg::SolverKind;
use rbfsurf::ordering::OrderingKind;
use rbfsurf::params::{Polynomial, ReconParams};
use rbfsurf::progress::{CancelFlag, NoProgress};
use rbfsurf::rbf::{CarrierKind, CarrierParams, Kernel, Support};
use rbfsurf::{ReconError, reconstruct};

fn check_closed(name: &str, rec: &rbfsurf::Reconstruction, components: usize, genus: i64) {
    let m = &rec.report.mesh;
    assert!(m.watertight && m.manifold, "{name}: {m:?}");
    assert_eq!(m.components, components, "{name}: {m:?}");
    assert_eq!(m.genus, Some(genus), "{name}: {m:?}");
    assert!(
        rec.report.residual.max < 1e-8,
        "{name}: residual {:?}",
        rec.report.residual
    );
}

#[test]
fn synthetic_shapes_give_closed_meshes_of_the_right_topology_near_the_truth() {
    for (name, n) in [("sphere", 3000), ("torus", 6000), ("two-spheres", 4000)] {
        let shape = Shape::by_name(name).unwrap();
        let cloud = shape.sample(n, 3);
        let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
        check_closed(name, &rec, shape.components(), shape.genus());
        // The shapes fill ~0.8 of the unit cube; the surface must stay within 1% of that of the truth.
        let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
        assert!(err < 0.01, "{name}: max vertex error {err}");
        // Outward normals: a step along the normal leaves the solid.
        for (v, nrm) in rec.mesh.vertices.iter().zip(&rec.mesh.normals).step_by(97) {
            let out = [
                v[0] + 0.01 * nrm[0],
                v[1] + 0.01 * nrm[1],
                v[2] + 0.01 * nrm[2],
            ];
            assert!(
                shape.signed_distance(&out) > shape.signed_distance(v),
                "{name}: inward normal at {v:?}"
            );
        }
    }
}

#[test]
fn points_far_from_the_origin_give_the_same_mesh_shifted() {
    let shape = Shape::by_name("torus").unwrap();
    let cloud = shape.sample(4000, 5);
    let shift = 1e6;
    let moved = PointCloud {
        points: cloud
            .points
            .iter()
            .map(|p| [p[0] + shift, p[1] + shift, p[2] + shift])
            .collect(),
        normals: cloud.normals.clone(),
        ..Default::default()
    };
    // Every grid triangle: the simplifier's collapse order follows rounding-level differences.
    let params = ReconParams {
        chord_error: rbfsurf::params::ChordTolerance::Off,
        ..Default::default()
    };
    let a = reconstruct(&cloud, &params, &NoProgress).unwrap();
    let b = reconstruct(&moved, &params, &NoProgress).unwrap();
    assert_eq!(a.mesh.triangles.len(), b.mesh.triangles.len());
    assert_eq!(a.report.mesh.genus, Some(1));
    assert_eq!(b.report.mesh.genus, Some(1));
    let mut va: Vec<[f64; 3]> = a.mesh.vertices.clone();
    let mut vb: Vec<[f64; 3]> = b
        .mesh
        .vertices
        .iter()
        .map(|p| [p[0] - shift, p[1] - shift, p[2] - shift])
        .collect();
    va.sort_by(|x, y| x.partial_cmp(y).unwrap());
    vb.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let worst = va
        .iter()
        .zip(&vb)
        .map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    // Normalisation removes the offset; what is left is rounding (≈1e-10 at 10⁶) that the
    // far field's Barnes–Hut lumping can amplify a little (measured 1.1e-6 on this torus of size
    // ~2), far below what single precision could keep at 10⁶ (0.06).
    assert!(worst < 1e-5, "shifted mesh differs by {worst}");
}

#[test]
fn the_order_of_the_points_in_the_file_does_not_change_the_mesh() {
    // The cleaned cloud is put in Morton order, so every later stage sees the same arrays:
    // before, the armadillo 10k with true normals came out genus 0, 2 and 0 from three shuffles
    // of its file (camel 2, 4, 4). Reversed and scrambled copies of a torus, with and without
    // normals (the estimated normals follow the order too), give the same mesh bit for bit.
    let shape = Shape::by_name("torus").unwrap();
    let cloud = shape.sample(3000, 9);
    let n = cloud.points.len();
    let reversed: Vec<usize> = (0..n).rev().collect();
    let scrambled: Vec<usize> = (0..n).map(|i| (i * 1237 + 11) % n).collect();
    let mut check = scrambled.clone();
    check.sort_unstable();
    assert!(
        check.iter().enumerate().all(|(i, &k)| i == k),
        "a permutation"
    );
    for normals in [true, false] {
        let base = PointCloud {
            normals: cloud.normals.clone().filter(|_| normals),
            ..cloud.clone()
        };
        let a = reconstruct(&base, &ReconParams::default(), &NoProgress).unwrap();
        assert_eq!(a.report.mesh.genus, Some(1));
        for order in [&reversed, &scrambled] {
            let b = reconstruct(&base.select(order), &ReconParams::default(), &NoProgress).unwrap();
            assert_eq!(a.mesh.triangles, b.mesh.triangles, "normals {normals}");
            assert_eq!(a.mesh.vertices, b.mesh.vertices, "normals {normals}");
        }
    }
}

#[test]
fn every_solver_ordering_and_polynomial_gives_the_same_surface() {
    let shape = Shape::by_name("sphere").unwrap();
    let cloud = shape.sample(1500, 11);
    let base = ReconParams {
        resolution: Some(48),
        ..Default::default()
    };
    let reference = reconstruct(&cloud, &base, &NoProgress).unwrap();
    for solver in [SolverKind::Envelope, SolverKind::Sparse, SolverKind::Ldl] {
        for ordering in [OrderingKind::None, OrderingKind::Bfs, OrderingKind::Rcm] {
            let p = ReconParams {
                solver,
                ordering,
                ..base.clone()
            };
            let rec = reconstruct(&cloud, &p, &NoProgress).unwrap();
            // The same mesh: same triangles, vertices equal to rounding (the solvers agree to
            // ~1e-12 in the coefficients; no grid corner is that close to the surface here).
            assert_eq!(
                rec.mesh.triangles, reference.mesh.triangles,
                "{solver} {ordering}"
            );
            let moved = rec
                .mesh
                .vertices
                .iter()
                .zip(&reference.mesh.vertices)
                .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max))
                .fold(0.0, f64::max);
            assert!(
                moved < 1e-9,
                "{solver} {ordering}: vertices moved by {moved}"
            );
            assert!(
                rec.report.residual.max < 1e-9,
                "{solver} {ordering}: {:?}",
                rec.report.residual
            );
        }
    }
    for carrier in [
        CarrierKind::Sphere,
        CarrierKind::Ellipsoid,
        CarrierKind::Local,
    ] {
        for kernel in Kernel::ALL {
            let p = ReconParams {
                carrier: CarrierParams {
                    kind: carrier,
                    ..Default::default()
                },
                kernel,
                polynomial: Polynomial::Linear,
                ..base.clone()
            };
            let rec = reconstruct(&cloud, &p, &NoProgress).unwrap();
            check_closed(&format!("{carrier} {kernel} linear"), &rec, 1, 0);
        }
    }
}

#[test]
fn kitten_is_one_closed_genus_one_surface() {
    let cloud =
        rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &Default::default()).unwrap();
    let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
    check_closed("kitten", &rec, 1, 1);
}

#[test]
fn bunny_is_close_to_its_reference_mesh() {
    use rbfsurf::mesh::compare::{CompareParams, Reference, compare};
    let cloud =
        rbfsurf::io::read_point_cloud(&common::data("bunny_cgal_10k.ply"), &Default::default())
            .unwrap();
    let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
    check_closed("bunny 10k", &rec, 1, 0);
    let reference = rbfsurf::io::read_mesh(&common::data("bunny00.off")).unwrap();
    let c = compare(
        &rec.mesh,
        Reference::Mesh(&reference),
        &CompareParams {
            samples: 20_000,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(c.chamfer_rel < 2e-3, "{c:?}");
    assert!(c.hausdorff_rel < 2e-2, "{c:?}");
}

#[test]
fn oversized_support_is_refused_before_allocating() {
    let cloud = Shape::by_name("sphere").unwrap().sample(20_000, 1);
    let p = ReconParams {
        support: Support::Radius(1.5),
        // Enough for 20,000 points (~132 MiB estimated), far from enough for a dense 20,000² system.
        max_memory_mib: 512,
        ..Default::default()
    };
    let err = reconstruct(&cloud, &p, &NoProgress)
        .err()
        .expect("must refuse");
    let msg = err.to_string();
    assert!(msg.contains("MiB") && msg.contains("--support"), "{msg}");
}

#[test]
fn cancellation_stops_the_work() {
    let cloud = Shape::by_name("sphere").unwrap().sample(2000, 1);
    let flag = CancelFlag::default();
    flag.cancel();
    let err = reconstruct(&cloud, &ReconParams::default(), &flag)
        .err()
        .expect("cancelled");
    assert!(matches!(err, ReconError::Cancelled), "{err:?}");
    assert!(err.to_string().contains("cancel"), "{err}");
}

#[test]
fn planar_points_with_a_linear_polynomial_are_refused_as_singular() {
    // A flat patch with normals is accepted (the local carrier orients it), but the linear polynomial
    // cannot be determined on a plane: the 4×4 border is singular.
    let points: Vec<[f64; 3]> = (0..400)
        .map(|i| [(i % 20) as f64 * 0.05, (i / 20) as f64 * 0.05, 0.3])
        .collect();
    let cloud = PointCloud {
        normals: Some(vec![[0.0, 0.0, 1.0]; points.len()]),
        points,
        ..Default::default()
    };
    let p = ReconParams {
        polynomial: Polynomial::Linear,
        resolution: Some(32),
        ..Default::default()
    };
    let err = reconstruct(&cloud, &p, &NoProgress)
        .err()
        .expect("singular border");
    assert!(err.to_string().contains("coplanar"), "{err}");
    let open = reconstruct(
        &cloud,
        &ReconParams {
            resolution: Some(32),
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    assert!(
        !open.report.mesh.watertight && open.report.mesh.components == 1,
        "{:?}",
        open.report.mesh
    );
}

#[test]
fn clouds_without_normals_get_estimated_oriented_normals() {
    let shape = Shape::by_name("torus").unwrap();
    let mut cloud = shape.sample(6000, 21);
    cloud.normals = None;
    let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
    check_closed("torus without normals", &rec, 1, 1);
    assert_eq!(rec.report.params.normals, "estimated");
    assert_eq!(rec.report.params.carrier, "local");
    let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
    assert!(err < 0.01, "max vertex error {err}");
}

#[test]
fn estimated_normals_agree_with_the_bunny_scan_normals() {
    use rbfsurf::normals::{NormalParams, estimate_oriented_normals};
    let cloud =
        rbfsurf::io::read_point_cloud(&common::data("bunny_cgal_10k.ply"), &Default::default())
            .unwrap();
    let truth = cloud.normals.as_ref().unwrap();
    let est = estimate_oriented_normals(&cloud.points, &NormalParams::default());
    let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let flips = est
        .iter()
        .zip(truth)
        .filter(|(a, b)| dot(a, b) < 0.0)
        .count();
    eprintln!(
        "bunny 10k: {flips} of {} estimated normals flipped",
        est.len()
    );
    // 4 at the ear tips with MST propagation; none since the patch + winding-number orientation.
    assert!(
        flips == 0,
        "{flips} of 10000 estimated normals point the wrong way"
    );
}

#[test]
fn a_single_range_image_gives_an_open_surface_on_the_data() {
    // One side of a sphere (a "range image": z above the centre), with normals.
    let shape = Shape::by_name("sphere").unwrap();
    let full = shape.sample(8000, 4);
    let keep: Vec<usize> = (0..full.points.len())
        .filter(|&i| full.points[i][2] > 0.55)
        .collect();
    let cloud = PointCloud {
        points: keep.iter().map(|&i| full.points[i]).collect(),
        normals: Some(
            keep.iter()
                .map(|&i| full.normals.as_ref().unwrap()[i])
                .collect(),
        ),
        ..Default::default()
    };
    let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
    let m = &rec.report.mesh;
    assert_eq!(rec.report.params.boundary, "trim");
    assert!(
        !m.watertight && m.components == 1 && m.boundary_loops == 1,
        "{m:?}"
    );
    let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
    assert!(err < 0.01, "open surface leaves the sphere by {err}");
    // Asking for a closed surface keeps the carrier's continuation.
    let closed = ReconParams {
        boundary: rbfsurf::params::Boundary::Closed,
        ..Default::default()
    };
    let rec = reconstruct(&cloud, &closed, &NoProgress).unwrap();
    assert_eq!(rec.report.params.boundary, "closed");
    assert_eq!(rec.report.polygonize.trimmed_triangles, 0);
}

#[test]
fn smoothing_and_outlier_removal_handle_a_noisy_scan() {
    use rbfsurf::geometry::synthetic::SplitMix64;
    let shape = Shape::by_name("sphere").unwrap();
    let mut cloud = shape.sample(6000, 8);
    let mut rng = SplitMix64(3);
    for p in cloud.points.iter_mut() {
        for v in p.iter_mut() {
            *v += 0.004 * (rng.next_f64() - 0.5);
        }
    }
    // 120 gross outliers: uniform in the cube but at least 0.05 (12% of the radius) off the surface.
    let mut added = 0;
    while added < 120 {
        let q = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
        if shape.signed_distance(&q).abs() > 0.05 {
            cloud.points.push(q);
            cloud.normals.as_mut().unwrap().push([0.0, 0.0, 1.0]);
            added += 1;
        }
    }
    let p = ReconParams {
        smoothing: rbfsurf::params::Smoothing::Lambda(0.05),
        outliers: Some(Default::default()),
        ..Default::default()
    };
    let rec = reconstruct(&cloud, &p, &NoProgress).unwrap();
    let removed = rec.report.input.outliers_removed;
    assert!((120..=200).contains(&removed), "{:?}", rec.report.input);
    check_closed_noisy(&rec);
    let err = common::max_vertex_error(&rec.mesh, |q| shape.signed_distance(q));
    assert!(err < 0.01, "smoothed surface leaves the sphere by {err}");
    // Smoothing approximates: the field no longer vanishes exactly at the data.
    assert!(rec.report.residual.max > 1e-6);
}

fn check_closed_noisy(rec: &rbfsurf::Reconstruction) {
    let m = &rec.report.mesh;
    assert!(
        m.watertight && m.components == 1 && m.genus == Some(0),
        "{m:?}"
    );
}
