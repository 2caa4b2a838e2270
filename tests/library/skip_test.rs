//! The polygonizer's skip test on real fitted fields: extracting the zero set of a
//! field fitted to a real scan with the narrow band (blocks and tiles skipped by
//! `may_contain_zero`, and tiles seeded from sign changes only, the default `Seeding`) gives exactly the mesh of extracting it everywhere, vertex for vertex, for the
//! default local carrier (with its winding-number far field), for several levels and for a
//! partition of unity of blocks, with normals and without.

use crate::common;

use rbfsurf::geometry::{Aabb, Point3, PointCloud};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::{FittedField, fit_field};
use rbfsurf::polygonize::{PolygonizeParams, ScalarField, Seeding, polygonize};
use rbfsurf::progress::NoProgress;
use rbfsurf::rbf::Blocks;
use rbfsurf::report::Timings;

/// The same field without any skipping.
struct Everywhere<'a>(&'a dyn ScalarField);

impl ScalarField for Everywhere<'_> {
    fn value(&self, p: &Point3) -> f64 {
        self.0.value(p)
    }
    fn gradient(&self, p: &Point3) -> Point3 {
        self.0.gradient(p)
    }
    fn values_in(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        self.0.values_in(region, points, out);
    }
    fn gradients_in(&self, region: &Aabb, points: &[Point3], out: &mut [Point3]) {
        self.0.gradients_in(region, points, out);
    }
    fn may_contain_zero(&self, _cell: &Aabb) -> bool {
        true
    }
}

fn fit(cloud: &PointCloud, params: &ReconParams) -> FittedField {
    fit_field(cloud, params, &NoProgress, &mut Timings::default()).unwrap()
}

/// Polygonizes `fit` with and without skipping on the pipeline's box (points plus support radius
/// plus three cells) and asserts the two meshes are identical; returns the share of the field
/// evaluations that skipping saved.
fn assert_skipping_changes_nothing(name: &str, fit: &FittedField, resolution: usize) -> f64 {
    let b = Aabb::from_points(&fit.points);
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    let domain = b.inflated(fit.support_radius + 3.0 * longest / resolution as f64);
    let pp = PolygonizeParams {
        resolution,
        ..Default::default()
    };
    let field = fit.field.as_ref();
    let (skipped, s) = polygonize(field, &domain, &pp, &NoProgress).unwrap();
    // The reference samples every tile: no skip test, no sign-change seeding.
    let every = PolygonizeParams {
        seeding: Seeding::EveryTile,
        ..pp
    };
    let (full, f) = polygonize(&Everywhere(field), &domain, &every, &NoProgress).unwrap();
    assert_eq!(f.blocks_active, f.blocks_total, "{name}");
    assert!(
        s.field_evaluations < f.field_evaluations,
        "{name}: nothing was skipped ({s:?} vs {f:?})"
    );
    assert!(!full.triangles.is_empty(), "{name}");
    assert_eq!(
        skipped.vertices.len(),
        full.vertices.len(),
        "{name}: {s:?} vs {f:?}"
    );
    assert!(skipped == full, "{name}: the narrow band changed the mesh");
    1.0 - s.field_evaluations as f64 / f.field_evaluations as f64
}

#[test]
fn skipping_changes_nothing_on_fields_fitted_to_real_scans() {
    let kitten =
        rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &Default::default()).unwrap();
    let bare = PointCloud {
        normals: None,
        ..kitten.clone()
    };
    let cases = [
        ("kitten, local carrier", &kitten, ReconParams::default()),
        (
            "kitten, 3 levels",
            &kitten,
            ReconParams {
                levels: 3,
                ..Default::default()
            },
        ),
        (
            "kitten, 4 blocks of 2 levels",
            &kitten,
            ReconParams {
                levels: 2,
                blocks: Blocks::MaxPoints(1500),
                ..Default::default()
            },
        ),
        ("kitten without normals", &bare, ReconParams::default()),
    ];
    for (name, cloud, params) in cases {
        let fit = fit(cloud, &params);
        let share = assert_skipping_changes_nothing(name, &fit, 64);
        assert!(
            share > 0.2,
            "{name}: skipping saved only {share} of the evaluations"
        );
    }
}

/// Every tile of a 4-cell grid over `fit`'s box (neighbours share their corners, as in the
/// polygonizer): the batched test's answers.
fn tile_answers(fit: &FittedField, cells: usize) -> (Vec<Aabb>, Vec<bool>) {
    let b = Aabb::from_points(&fit.points).inflated(2.0 * fit.support_radius);
    let e = b.extent();
    let h = e.iter().fold(0.0f64, |a, &x| a.max(x)) / cells as f64;
    let n = e.map(|x| (x / h).ceil() as usize);
    let corner = |i: usize, k: usize| b.min[k] + i as f64 * h;
    let mut tiles = Vec::new();
    for k in (0..n[2]).step_by(4) {
        for j in (0..n[1]).step_by(4) {
            for i in (0..n[0]).step_by(4) {
                tiles.push(Aabb {
                    min: [corner(i, 0), corner(j, 1), corner(k, 2)],
                    max: [corner(i + 4, 0), corner(j + 4, 1), corner(k + 4, 2)],
                });
            }
        }
    }
    let mut each = vec![false; tiles.len()];
    fit.field.may_contain_zero_each(&tiles, &mut each);
    (tiles, each)
}

#[test]
fn the_batched_skip_test_answers_as_the_per_tile_one() {
    let kitten =
        rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &Default::default()).unwrap();
    for (name, params) in [
        ("local carrier", ReconParams::default()),
        (
            "3 levels",
            ReconParams {
                levels: 3,
                ..Default::default()
            },
        ),
    ] {
        let fit = fit(&kitten, &params);
        let (tiles, each) = tile_answers(&fit, 96);
        let single: Vec<bool> = tiles
            .iter()
            .map(|t| fit.field.may_contain_zero(t))
            .collect();
        assert_eq!(each, single, "{name}");
        let (yes, no) = (
            each.iter().filter(|&&a| a).count(),
            each.iter().filter(|&&a| !a).count(),
        );
        assert!(
            yes > 0 && no > 0,
            "{name}: {yes} tiles may hold the surface, {no} not"
        );
    }
}
