//! The local carrier evaluated per tile from a gathered list of points (no k-d tree
//! query per grid corner) against the reference path (an index query per point), on fields fitted
//! to real scans: every corner of a lattice of polygonizer-sized tiles around the data, and points
//! inside them, get the same value and gradient bit for bit, both where `R` holds at least K
//! usable points and where the weights widen to the K nearest ones.

use crate::common;

use rbfsurf::geometry::{Aabb, Point3, PointCloud, dist2};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::{FittedField, fit_field};
use rbfsurf::progress::NoProgress;
use rbfsurf::rbf::carrier::{FAR_NEIGHBOURS, LocalCarrier, NearPoints};
use rbfsurf::rbf::{Carrier, RbfField};
use rbfsurf::report::Timings;

/// The reference: the points within `R` of `x` from the index, ascending (the order the
/// polygonizer's sorted candidate lists give).
fn reference(field: &RbfField, l: &LocalCarrier, x: &Point3) -> (f64, Point3, usize) {
    let mut hits = Vec::new();
    field
        .carrier_index
        .within(x, field.carrier_radius, &mut hits);
    hits.sort_unstable();
    let within = hits
        .iter()
        .filter(|&&j| {
            l.normals()[j as usize] != [0.0; 3]
                && dist2(*x, l.points()[j as usize]) < field.carrier_radius.powi(2)
        })
        .count();
    let (v, g) = l.value_gradient_with(x, &hits);
    (v, g, within)
}

/// Compares every corner of the tiles (edge `tile`) whose centre lies within `reach` of a data
/// point, plus one point inside each tile and one outside it; returns how many points were
/// compared and how many of them had fewer than K usable points within `R` and got their K
/// nearest from the tile's list.
fn compare_tiles(name: &str, field: &RbfField, tile: f64, reach: f64) -> (usize, usize) {
    let Carrier::Local(l) = &field.carrier else {
        panic!("{name}: not a local carrier")
    };
    let data = Aabb::from_points(l.points()).inflated(reach);
    let n = data.extent().map(|e| (e / tile).ceil() as usize);
    let mut near = NearPoints::new();
    let (mut compared, mut widened) = (0, 0);
    let mut nn = Vec::new();
    for t in 0..n[0] * n[1] * n[2] {
        let t3 = [t % n[0], (t / n[0]) % n[1], t / (n[0] * n[1])];
        let min: Point3 = [0, 1, 2].map(|a| data.min[a] + t3[a] as f64 * tile);
        let region = Aabb {
            min,
            max: min.map(|v| v + tile),
        };
        field.carrier_index.nearest_k(&region.center(), 1, &mut nn);
        if nn[0].1 > reach {
            continue;
        }
        l.gather(&region, &mut near);
        let mut points: Vec<Point3> = (0..125)
            .map(|c| {
                let c3 = [c % 5, (c / 5) % 5, c / 25];
                [0, 1, 2].map(|a| min[a] + c3[a] as f64 * tile / 4.0)
            })
            .collect();
        points.push([0, 1, 2].map(|a| min[a] + tile * [0.31, 0.77, 0.52][a]));
        // Outside the region: served by the index queries.
        points.push([0, 1, 2].map(|a| min[a] + tile * [1.6, -0.3, 0.5][a]));
        for x in &points {
            let (v, g, within) = reference(field, l, x);
            let fast = l.value_gradient_near(x, &mut near);
            let value = l.value_near(x, &mut near);
            assert_eq!(
                (v.to_bits(), g.map(f64::to_bits)),
                (fast.0.to_bits(), fast.1.map(f64::to_bits)),
                "{name}: at {x:?} (tile {region:?}): {v} {g:?} vs {fast:?}"
            );
            assert_eq!(value.to_bits(), v.to_bits(), "{name}: value at {x:?}");
            compared += 1;
            widened += usize::from(within < FAR_NEIGHBOURS && near.serves_nearest());
        }
    }
    (compared, widened)
}

/// The field of `cloud` fitted with the default parameters.
fn fitted(cloud: &PointCloud) -> FittedField {
    fit_field(
        cloud,
        &ReconParams::default(),
        &NoProgress,
        &mut Timings::default(),
    )
    .unwrap()
}

#[test]
fn tile_lists_give_the_index_queries_values_bit_for_bit_on_real_scans() {
    let kitten =
        rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &Default::default()).unwrap();
    let bunny =
        rbfsurf::io::read_point_cloud(&common::data("bunny_cgal_10k.ply"), &Default::default())
            .unwrap();
    let bare = PointCloud {
        normals: None,
        ..kitten.clone()
    };
    for (name, cloud) in [
        ("kitten", &kitten),
        ("kitten without normals", &bare),
        ("bunny 10k", &bunny),
    ] {
        let fit = fitted(cloud);
        let field = fit.rbf.as_ref().unwrap();
        let r = fit.support_radius;
        // Tiles as the polygonizer's (4 cells of about R / 3.75), out to twice R from the data
        // where the far field takes over, and a few larger ones.
        for (tile, reach) in [(4.0 * r / 3.75, 2.0 * r), (3.0 * r, 1.5 * r)] {
            let (compared, widened) = compare_tiles(name, field, tile, reach);
            assert!(
                compared > 1000 && widened > compared / 5 && widened < compared,
                "{name}: {compared} points compared, {widened} with fewer than K within R"
            );
        }
    }
}

/// A field prepared for a tile (`ScalarField::prepare`, what the polygonizer probes, samples and
/// refines on) answers its first few points with per-point queries and the rest from gathered
/// lists: both must give the values of one batched `values_in` over the same tile bit for bit, and
/// the gradients of `gradients_in`; and agree with the plain per-point `value`/`gradient` to
/// rounding.
#[test]
fn a_prepared_tile_gives_the_batched_values_bit_for_bit() {
    use rbfsurf::polygonize::ScalarField;
    let kitten =
        rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &Default::default()).unwrap();
    let fit = fitted(&kitten);
    let field = fit.rbf.as_ref().unwrap();
    let r = fit.support_radius;
    let tile = 4.0 * r / 3.75;
    let (mut tiles, mut single) = (0, 0);
    for (k, p) in kitten.points.iter().enumerate().step_by(97) {
        // A tile around a data point, shifted off the grid of the points' coordinates.
        let min: Point3 = [0, 1, 2].map(|a| p[a] - tile * [0.3, 0.55, 0.7][a]);
        let region = Aabb {
            min,
            max: min.map(|v| v + tile),
        };
        let pts: Vec<Point3> = (0..40)
            .map(|i| {
                let u = [0.13, 0.37, 0.71]
                    .map(|s: f64| ((i as f64 + 1.0) * s + k as f64 * 0.01).fract());
                [0, 1, 2].map(|a| min[a] + u[a] * tile)
            })
            .collect();
        let mut batched = vec![0.0; pts.len()];
        field.values_in(&region, &pts, &mut batched);
        // The probe's pattern: one centre, then 8 corners, then the rest in one call.
        let mut prepared = field.prepare(&region);
        let mut got = vec![0.0; pts.len()];
        prepared.values(&pts[..1], &mut got[..1]);
        prepared.values(&pts[1..9], &mut got[1..9]);
        prepared.values(&pts[9..], &mut got[9..]);
        single += 9;
        for (i, x) in pts.iter().enumerate() {
            assert_eq!(got[i].to_bits(), batched[i].to_bits(), "value {i} at {x:?}");
            let plain = field.value(x);
            assert!(
                (plain - got[i]).abs() <= 1e-12 * (1.0 + plain.abs()),
                "{plain} vs {}",
                got[i]
            );
        }
        let mut g_batched = vec![[0.0; 3]; pts.len()];
        field.gradients_in(&region, &pts, &mut g_batched);
        let mut g_got = vec![[0.0; 3]; pts.len()];
        prepared.gradients(&pts, &mut g_got);
        for (i, x) in pts.iter().enumerate() {
            assert_eq!(
                g_got[i].map(f64::to_bits),
                g_batched[i].map(f64::to_bits),
                "gradient {i}"
            );
            let plain = field.gradient(x);
            for a in 0..3 {
                assert!((plain[a] - g_got[i][a]).abs() <= 1e-9 * (1.0 + plain[a].abs()));
            }
        }
        tiles += 1;
    }
    assert!(tiles > 40 && single > 300, "{tiles} tiles");
}

/// A region several supports wide is split into parts, each gathered on its own, and a
/// partition-of-unity field (blocks) is prepared the same way: every point must get the bits of
/// the per-point path (a fresh preparation answers the first points of each part with sorted
/// index queries), whatever part or tile it falls in, values and gradients, and the gradient of
/// the plain per-point `gradient` to rounding.
#[test]
fn split_regions_and_block_fields_give_the_per_point_values_bit_for_bit() {
    use rbfsurf::polygonize::ScalarField;
    use rbfsurf::rbf::{Blocks, Correction};
    let bunny =
        rbfsurf::io::read_point_cloud(&common::data("bunny_cgal_10k.ply"), &Default::default())
            .unwrap();
    let global = fitted(&bunny);
    let blocked = fit_field(
        &bunny,
        &ReconParams {
            blocks: Blocks::MaxPoints(2500),
            ..Default::default()
        },
        &NoProgress,
        &mut Timings::default(),
    )
    .unwrap();
    let field = blocked.rbf.as_ref().unwrap();
    assert!(matches!(&field.correction, Correction::Blocks(b) if b.len() >= 4));
    let mut compared = 0;
    for (name, fit) in [("global", &global), ("blocks", &blocked)] {
        let field = fit.rbf.as_ref().unwrap();
        let r = fit.support_radius;
        for (k, p) in bunny.points.iter().enumerate().step_by(211) {
            // Tiles of 1, 3 and 8 supports (one part, 2³ and 4³ parts) around a data point,
            // with enough points that most parts gather their lists.
            for (width, count) in [(r, 60), (3.0 * r, 150), (8.0 * r, 1000)] {
                let min: Point3 = [0, 1, 2].map(|a| p[a] - width * [0.45, 0.6, 0.35][a]);
                let region = Aabb {
                    min,
                    max: min.map(|v| v + width),
                };
                let pts: Vec<Point3> = (0..count)
                    .map(|i| {
                        let u = [0.19, 0.43, 0.67]
                            .map(|s: f64| ((i as f64 + 1.0) * s + k as f64 * 0.003).fract());
                        [0, 1, 2].map(|a| min[a] + u[a] * width)
                    })
                    .collect();
                let mut prepared = field.prepare(&region);
                let mut got = vec![0.0; pts.len()];
                prepared.values(&pts, &mut got);
                let mut grads = vec![[0.0; 3]; pts.len()];
                prepared.gradients(&pts, &mut grads);
                for (i, x) in pts.iter().enumerate() {
                    let mut single = [0.0];
                    field.prepare(&region).values(&pts[i..=i], &mut single);
                    assert_eq!(
                        got[i].to_bits(),
                        single[0].to_bits(),
                        "{name}: value at {x:?} in a tile {width} wide"
                    );
                    let mut single_gradient = [[0.0; 3]];
                    (field.prepare(&region)).gradients(&pts[i..=i], &mut single_gradient);
                    assert_eq!(
                        grads[i].map(f64::to_bits),
                        single_gradient[0].map(f64::to_bits),
                        "{name}: gradient at {x:?} in a tile {width} wide"
                    );
                    let plain = field.gradient(x);
                    for a in 0..3 {
                        assert!(
                            (plain[a] - grads[i][a]).abs() <= 1e-9 * (1.0 + plain[a].abs()),
                            "{name}: gradient at {x:?}: {plain:?} vs {:?}",
                            grads[i]
                        );
                    }
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 8000, "{compared}");
}
