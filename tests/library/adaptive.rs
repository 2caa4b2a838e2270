//! The adaptive two-level extractor (`Extraction::Adaptive`, issue 14 item 1): closed, manifold,
//! oriented and of the right topology on analytic shapes and on a field fitted to a real scan,
//! deterministic, on the zero set, with fewer field values than the uniform grid; cancellable.

use crate::common;

use rbfsurf::geometry::{Aabb, Point3, PointCloud, TriMesh, norm};
use rbfsurf::mesh::{analyze, signed_volume};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::fit_field;
use rbfsurf::polygonize::{
    Extraction, PolygonizeError, PolygonizeParams, PolygonizeStats, ScalarField, polygonize,
};
use rbfsurf::progress::{CancelFlag, NoProgress};
use rbfsurf::report::Timings;

/// Signed distances (1-Lipschitz, so `|f(centre)| ≤ half diagonal` is a safe skip test).
#[derive(Clone, Copy)]
enum Shape {
    /// Torus around z, radii `big`, `small`.
    Torus { big: f64, small: f64 },
    /// Two balls of radius `r` on the x axis, centres `±(r + gap / 2)`.
    TwoBalls { r: f64, gap: f64 },
    /// A slab `|z| ≤ t / 2` cut to `|x|, |y| ≤ 0.6`: flat faces, sharp edges, thin.
    Plate { t: f64 },
}

impl Shape {
    fn distance(&self, p: &Point3) -> f64 {
        match *self {
            Shape::Torus { big, small } => {
                let q = (p[0] * p[0] + p[1] * p[1]).sqrt() - big;
                (q * q + p[2] * p[2]).sqrt() - small
            }
            Shape::TwoBalls { r, gap } => {
                let c = r + gap / 2.0;
                let a = norm([p[0] - c, p[1], p[2]]) - r;
                let b = norm([p[0] + c, p[1], p[2]]) - r;
                a.min(b)
            }
            Shape::Plate { t } => {
                let d = [p[0].abs() - 0.6, p[1].abs() - 0.6, p[2].abs() - t / 2.0];
                let out = norm(d.map(|x| x.max(0.0)));
                out + d[0].max(d[1]).max(d[2]).min(0.0)
            }
        }
    }
}

impl ScalarField for Shape {
    fn value(&self, p: &Point3) -> f64 {
        self.distance(p)
    }
    fn gradient(&self, p: &Point3) -> Point3 {
        let e = 1e-7;
        [0, 1, 2].map(|k| {
            let (mut a, mut b) = (*p, *p);
            a[k] += e;
            b[k] -= e;
            (self.distance(&a) - self.distance(&b)) / (2.0 * e)
        })
    }
    fn may_contain_zero(&self, cell: &Aabb) -> bool {
        self.distance(&cell.center()).abs() <= 0.5 * cell.diagonal()
    }
}

fn cube() -> Aabb {
    Aabb {
        min: [-1.0; 3],
        max: [1.0; 3],
    }
}

fn extract(
    field: &dyn ScalarField,
    extraction: Extraction,
    res: usize,
) -> (TriMesh, PolygonizeStats) {
    let params = PolygonizeParams {
        resolution: res,
        extraction,
        ..Default::default()
    };
    polygonize(field, &cube(), &params, &NoProgress).unwrap()
}

const ADAPTIVE: Extraction = Extraction::Adaptive { tolerance: 0.002 };

/// Largest `|f| / |∇f|` at the vertices.
fn off_surface(field: &dyn ScalarField, mesh: &TriMesh) -> f64 {
    (mesh.vertices.iter())
        .map(|p| field.value(p).abs() / norm(field.gradient(p)).max(1e-12))
        .fold(0.0, f64::max)
}

/// The adaptive mesh's vertices lie on the zero set as the uniform grid's do (both placed on their
/// edges by 2 root-finding steps), and it evaluated fewer field values.
fn assert_placed_and_cheaper(
    name: &str,
    field: &dyn ScalarField,
    (mesh, stats): (&TriMesh, &PolygonizeStats),
    (uniform, u): (&TriMesh, &PolygonizeStats),
) {
    let (off, off_u) = (off_surface(field, mesh), off_surface(field, uniform));
    assert!(
        off <= 2.0 * off_u + 1e-9,
        "{name}: vertices {off} off, uniform {off_u}"
    );
    assert!(
        stats.field_evaluations < u.field_evaluations,
        "{name}: {stats:?} vs {u:?}"
    );
}

#[test]
fn analytic_shapes_come_out_closed_with_their_topology() {
    let cases = [
        (
            "torus",
            Shape::Torus {
                big: 0.55,
                small: 0.2,
            },
            1,
            1,
        ),
        ("two balls", Shape::TwoBalls { r: 0.35, gap: 0.1 }, 2, 0),
        ("plate", Shape::Plate { t: 0.12 }, 1, 0),
    ];
    for (name, shape, components, genus) in cases {
        let (mesh, stats) = extract(&shape, ADAPTIVE, 64);
        let (uniform, u) = extract(&shape, Extraction::Uniform, 64);
        let t = analyze(&mesh);
        assert!(t.watertight && t.manifold && t.oriented, "{name}: {t:?}");
        assert_eq!(t.components, components, "{name}: {t:?}");
        assert_eq!(t.genus, Some(genus), "{name}: {t:?}");
        assert!(signed_volume(&mesh) > 0.0, "{name}: wound inwards");
        // Within a few per cent of the uniform grid's enclosed volume.
        let (v, vu) = (signed_volume(&mesh), signed_volume(&uniform));
        assert!(
            (v - vu).abs() < 0.03 * vu,
            "{name}: volume {v} vs uniform {vu}"
        );
        assert_placed_and_cheaper(name, &shape, (&mesh, &stats), (&uniform, &u));
    }
}

#[test]
fn flat_parts_cost_far_less_than_on_the_uniform_grid() {
    // The plate's faces are planes: its cubes stay unsplit except along the edges.
    let plate = Shape::Plate { t: 0.3 };
    let (mesh, a) = extract(&plate, ADAPTIVE, 96);
    let (uniform, u) = extract(&plate, Extraction::Uniform, 96);
    assert!(
        (a.field_evaluations as f64) < 0.6 * u.field_evaluations as f64,
        "{a:?} vs {u:?}"
    );
    assert!(
        (mesh.triangles.len() as f64) < 0.7 * uniform.triangles.len() as f64,
        "{} vs {}",
        mesh.triangles.len(),
        uniform.triangles.len()
    );
}

#[test]
fn a_field_fitted_to_a_real_scan_gives_the_uniform_topology_deterministically() {
    for normals in [true, false] {
        let mut cloud =
            rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &Default::default())
                .unwrap();
        if !normals {
            cloud = PointCloud {
                normals: None,
                ..cloud
            };
        }
        let fit = fit_field(
            &cloud,
            &ReconParams::default(),
            &NoProgress,
            &mut Timings::default(),
        )
        .unwrap();
        let b = Aabb::from_points(&fit.points).inflated(2.0 * fit.support_radius);
        let field = fit.field.as_ref();
        let run = |extraction| {
            let params = PolygonizeParams {
                resolution: 96,
                extraction,
                ..Default::default()
            };
            polygonize(field, &b, &params, &NoProgress).unwrap()
        };
        let adaptive = Extraction::Adaptive {
            tolerance: fit.support.spacing,
        };
        let (mesh, stats) = run(adaptive);
        let (again, _) = run(adaptive);
        assert!(mesh == again, "normals {normals}: not deterministic");
        let (uniform, u) = run(Extraction::Uniform);
        let (t, tu) = (analyze(&mesh), analyze(&uniform));
        assert!(
            t.watertight && t.manifold && t.oriented,
            "normals {normals}: {t:?}"
        );
        assert_eq!(
            (t.components, t.genus),
            (tu.components, tu.genus),
            "normals {normals}"
        );
        let name = format!("kitten, normals {normals}");
        assert_placed_and_cheaper(&name, field, (&mesh, &stats), (&uniform, &u));
    }
}

#[test]
fn adaptive_extraction_can_be_cancelled() {
    let flag = CancelFlag::default();
    flag.cancel();
    let params = PolygonizeParams {
        resolution: 64,
        extraction: ADAPTIVE,
        ..Default::default()
    };
    let shape = Shape::Torus {
        big: 0.55,
        small: 0.2,
    };
    let err = polygonize(&shape, &cube(), &params, &flag).unwrap_err();
    assert_eq!(err, PolygonizeError::Cancelled);
}
