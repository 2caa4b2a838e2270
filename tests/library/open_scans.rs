//! Open scans and floaters end to end: a range image with holes gives one manifold sheet on the data
//! with one boundary loop per border or hole, polygonized only in the data band; two separate objects
//! stay two closed components; the border is peeled back to the data without changing topology.

use rbfsurf::geometry::PointCloud;
use rbfsurf::geometry::synthetic::{Shape, SplitMix64};
use rbfsurf::params::ReconParams;
use rbfsurf::progress::NoProgress;
use rbfsurf::reconstruct;
use rbfsurf::spatial::KdTree;

/// The height field `z = h(x, y)` of the range image and its upward unit normal.
fn height(x: f64, y: f64) -> (f64, [f64; 3]) {
    let z = 0.08 * (4.0 * x).sin() * (3.0 * y).cos();
    let (dx, dy) = (
        0.32 * (4.0 * x).cos() * (3.0 * y).cos(),
        -0.24 * (4.0 * x).sin() * (3.0 * y).sin(),
    );
    let l = (dx * dx + dy * dy + 1.0).sqrt();
    (z, [-dx / l, -dy / l, 1.0 / l])
}

/// A jittered `n × n` range image over the unit square with two round holes (radii 0.10 and 0.08,
/// about 3× the support radius), with normals.
fn range_image_with_holes(n: usize) -> PointCloud {
    let mut rng = SplitMix64(11);
    let holes = [([0.3, 0.35], 0.10), ([0.7, 0.65], 0.08)];
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for i in 0..n {
        for j in 0..n {
            let x = (i as f64 + 0.3 * rng.next_f64()) / n as f64;
            let y = (j as f64 + 0.3 * rng.next_f64()) / n as f64;
            if holes
                .iter()
                .any(|(c, r)| (x - c[0]).powi(2) + (y - c[1]).powi(2) < r * r)
            {
                continue;
            }
            let (z, nrm) = height(x, y);
            points.push([x, y, z]);
            normals.push(nrm);
        }
    }
    PointCloud {
        points,
        normals: Some(normals),
        ..Default::default()
    }
}

#[test]
fn a_range_image_with_holes_gives_one_manifold_sheet_polygonized_in_the_band() {
    let cloud = range_image_with_holes(100);
    // Every grid triangle, so the vertex statistics below are the polygonizer's (the simplifier
    // keeps a subset of the vertices that leans towards the locked border).
    let params = ReconParams {
        chord_error: rbfsurf::params::ChordTolerance::Off,
        ..Default::default()
    };
    let rec = reconstruct(&cloud, &params, &NoProgress).unwrap();
    let (m, p) = (&rec.report.mesh, &rec.report.polygonize);
    assert_eq!(rec.report.params.boundary, "trim");
    assert!(p.unsupported_share.is_some_and(|s| s > 0.02), "{p:?}");
    // Seen from its middle, the sheet leaves the space above and below it empty.
    assert!(p.empty_cone_deg.is_some_and(|d| d > 60.0), "{p:?}");
    // A one-sided sheet encloses no volume.
    assert!(p.enclosed_share.is_some_and(|e| e < 0.15), "{p:?}");
    // One sheet with two holes: a disk minus two disks, χ = 1 − 2, three boundary loops.
    assert!(!m.watertight && m.manifold && m.oriented, "{m:?}");
    assert_eq!(
        (m.components, m.boundary_loops, m.euler),
        (1, 3, -1),
        "{m:?}"
    );
    assert_eq!((m.non_manifold_vertices, m.non_manifold_edges), (0, 0));
    // Only the band was polygonized: little was thrown away.
    assert!(
        (p.triangles_polygonized as f64) < 1.15 * p.triangles_before_simplify as f64,
        "{p:?} vs {} kept",
        p.triangles_before_simplify
    );
    // On the data: every vertex on the height field and within the support radius (plus a cell)
    // of a data point.
    let tree = KdTree::build(&cloud.points).unwrap();
    let reach = rec.report.params.support_input_units + 2.0 * p.cell_size;
    let mut sum = 0.0;
    for v in &rec.mesh.vertices {
        let err = (v[2] - height(v[0], v[1]).0).abs();
        sum += err;
        // A vertex is on a grid edge with a sign change: never more than a cell off.
        assert!(err < p.cell_size, "vertex {v:?} is {err} off the surface");
        let (_, d) = tree.nearest_one(v).unwrap();
        assert!(
            d <= reach,
            "vertex {v:?} is {d} from the data (reach {reach})"
        );
    }
    let mean = sum / rec.mesh.vertices.len() as f64;
    assert!(mean < 1e-4, "mean vertex error {mean}");
}

#[test]
fn two_spheres_without_normals_stay_two_closed_components() {
    let shape = Shape::by_name("two-spheres").unwrap();
    let mut cloud = shape.sample(4000, 7);
    cloud.normals = None;
    let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
    let m = &rec.report.mesh;
    assert!(m.watertight && m.manifold, "{m:?}");
    assert_eq!((m.components, m.genus), (2, Some(0)), "{m:?}");
    assert_eq!(rec.report.polygonize.floaters_removed, 0);
    assert_eq!(rec.report.params.boundary, "closed");
}

/// A sphere sampled only outside ten caps of 18° half-angle spread over it ("oceans", a quarter of
/// the surface), without normals: the data are taken all around, so the holes are closed (the
/// coarse pass finds far more than 2% of its surface unsupported, but no empty cone wider than the
/// caps).
#[test]
fn a_sphere_with_wide_holes_all_round_is_closed_not_trimmed() {
    let shape = Shape::by_name("sphere").unwrap();
    let cloud = shape.sample(12_000, 5);
    let caps: Vec<[f64; 3]> = (0..10)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / 10.0;
            let r = (1.0 - z * z).sqrt();
            let phi = std::f64::consts::PI * (1.0 + 5f64.sqrt()) * i as f64;
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect();
    let c = rbfsurf::geometry::Aabb::from_points(&cloud.points).center();
    let cut = 18f64.to_radians().cos();
    let outside = |p: &[f64; 3]| {
        let d: [f64; 3] = std::array::from_fn(|k| p[k] - c[k]);
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        (caps.iter()).all(|a| (d[0] * a[0] + d[1] * a[1] + d[2] * a[2]) / l < cut)
    };
    let points: Vec<[f64; 3]> = cloud.points.iter().copied().filter(outside).collect();
    assert!(points.len() < 9_600, "{} points kept", points.len());
    let rec = reconstruct(
        &PointCloud {
            points,
            ..Default::default()
        },
        &ReconParams::default(),
        &NoProgress,
    )
    .unwrap();
    let (m, p) = (&rec.report.mesh, &rec.report.polygonize);
    // Surrounded: closed without the coarse pass (which found more than 2 % of its area
    // unsupported, enough to trim data that do not surround their middle).
    assert!(p.empty_cone_deg.is_some_and(|d| d < 25.0), "{p:?}");
    assert!(p.unsupported_share.is_none(), "{p:?}");
    assert_eq!(rec.report.params.boundary, "closed");
    assert!(m.watertight && m.manifold, "{m:?}");
    assert_eq!((m.components, m.genus), (1, Some(0)), "{m:?}");
}

/// The open-or-closed rule on a closed object whose middle the data do not surround: an elk whose
/// crown, legs and the hole through its body leave a cone of about 40° empty. Its thin crown puts
/// 4 % of a coarse pass's surface farther than R from the data, so that pass alone trimmed it open
/// with a hole; its oriented points enclose a volume (winding number ≥ ¾ over 30 % of where it is
/// clearly non-zero), so it is closed. Data taken all around a closed object give a closed surface.
#[test]
fn a_closed_elk_sampled_all_around_without_normals_comes_out_closed() {
    let cloud =
        rbfsurf::io::read_point_cloud(std::path::Path::new("data/elk-3k.xyz"), &Default::default())
            .unwrap();
    assert!(cloud.normals.is_none());
    let rec = reconstruct(&cloud, &ReconParams::default(), &NoProgress).unwrap();
    let (m, p) = (&rec.report.mesh, &rec.report.polygonize);
    assert!(p.empty_cone_deg.is_some_and(|d| d > 25.0), "{p:?}");
    assert!(p.enclosed_share.is_some_and(|e| e > 0.15), "{p:?}");
    assert_eq!(rec.report.params.boundary, "closed");
    assert!(m.watertight && m.manifold && m.oriented, "{m:?}");
    assert_eq!((m.components, m.boundary_loops), (1, 0), "{m:?}");
}

/// Mean distance from the border vertices (on an edge of one triangle) of `mesh` to the data.
fn border_reach(mesh: &rbfsurf::geometry::TriMesh, tree: &KdTree) -> f64 {
    let mut count = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let mut border: Vec<u32> = (count.iter().filter(|(_, n)| **n == 1))
        .flat_map(|((a, b), _)| [*a, *b])
        .collect();
    border.sort_unstable();
    border.dedup();
    let sum: f64 = (border.iter())
        .map(|&v| tree.nearest_one(&mesh.vertices[v as usize]).unwrap().1)
        .sum();
    sum / border.len() as f64
}

/// The border of an open scan is peeled back towards the data (`--border-reach`, default half a
/// support radius) and keeps the sheet's topology: the same pieces, holes and Euler characteristic
/// as the trim alone (`border_reach` 1), with the border vertices nearer the data.
#[test]
fn the_border_of_a_range_image_is_peeled_back_to_its_data() {
    let cloud = range_image_with_holes(100);
    let tree = KdTree::build(&cloud.points).unwrap();
    let run = |border_reach| {
        let params = ReconParams {
            border_reach,
            ..Default::default()
        };
        reconstruct(&cloud, &params, &NoProgress).unwrap()
    };
    let (trim, peel) = (run(1.0), run(ReconParams::default().border_reach));
    let (a, b) = (&trim.report.mesh, &peel.report.mesh);
    assert_eq!(trim.report.polygonize.peeled_triangles, 0);
    assert!(peel.report.polygonize.peeled_triangles > 0);
    assert_eq!(
        (a.components, a.boundary_loops, a.euler),
        (b.components, b.boundary_loops, b.euler)
    );
    assert!(
        b.manifold && (b.non_manifold_vertices, b.non_manifold_edges) == (0, 0),
        "{b:?}"
    );
    let r = peel.report.params.support_input_units;
    let (before, after) = (
        border_reach(&trim.mesh, &tree),
        border_reach(&peel.mesh, &tree),
    );
    assert!(after < 0.8 * before, "border {before} → {after} (R = {r})");
}
