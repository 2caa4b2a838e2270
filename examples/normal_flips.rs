//! Normal orientation measured against known normals: for every shared data set that has normals
//! and for generated shapes (thin, subsampled, noisy and open variants), estimate oriented normals
//! from the positions alone and count
//! - `flips`: `n_est · n_true < 0` (orientation errors),
//! - `off18`: unsigned angle to the true line above 18° (PCA errors, independent of orientation).
//!
//! Run with `cargo run --release --example normal_flips [-- DATA_DIR]` (default data directory
//! `../shared/data`; `WRITE_DIR=DIR` writes each set with its estimated normals as
//! `DIR/NAME-est.ply`; further PLY files with normals may follow it). Sets whose file is missing are skipped. `ONLY=text` keeps the generated sets
//! whose name contains `text`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rbfsurf::geometry::synthetic::{Coverage, Defects, Shape, apply_defects};
use rbfsurf::geometry::{Point3, PointCloud, dot, norm};
use rbfsurf::normals::{NormalParams, estimate_oriented_normals, inconsistent_fraction};
use rbfsurf::spatial::{IndexKind, build_index};

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared/data"));
    println!("| set | points | flips | off > 18° | truth opposed pairs | seconds |");
    println!("|---|---:|---:|---:|---:|---:|");
    for name in [
        "kitten",
        "bunny_cgal_10k",
        "bunny_cgal",
        "hippo1",
        "hippo2",
        "oni",
    ] {
        let path = dir.join(format!("{name}.ply"));
        if let Some(cloud) = read(&path) {
            row(name, &cloud);
        }
    }
    // Further PLY files with normals given after the data directory (e.g. the real-scan suite's
    // statue samples, target/realscans/*-n.ply).
    for path in std::env::args().skip(2).map(PathBuf::from) {
        if let Some(cloud) = read(&path) {
            let name = path
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into());
            row(&name, &cloud);
        }
    }
    let only = std::env::var("ONLY").ok();
    for (name, cloud) in generated() {
        if only.as_ref().is_some_and(|o| !name.contains(o.as_str())) {
            continue;
        }
        row(&name, &cloud);
    }
}

fn read(path: &Path) -> Option<PointCloud> {
    let cloud = rbfsurf::io::read_point_cloud(path, &Default::default()).ok()?;
    cloud.normals.is_some().then_some(cloud)
}

/// One table row: estimate from positions only and compare with the given normals.
fn row(name: &str, cloud: &PointCloud) {
    let truth = cloud.normals.as_ref().expect("sets with normals");
    let t = Instant::now();
    let est = estimate_oriented_normals(&cloud.points, &NormalParams::default());
    let secs = t.elapsed().as_secs_f64();
    let (flips, off) = errors(&est, truth);
    if let Some(dir) = std::env::var_os("WRITE_DIR") {
        let mut out = cloud.clone();
        out.normals = Some(est.clone());
        let path = PathBuf::from(dir).join(format!("{}-est.ply", name.replace(' ', "_")));
        rbfsurf::io::write_points_ply(&path, &out).expect("write estimated normals");
    }
    let index = build_index(&cloud.points, IndexKind::KdTree, 8).expect("index");
    let opposed = inconsistent_fraction(&cloud.points, truth, 8, |p, k, out| {
        index.nearest_k(p, k, out)
    });
    println!(
        "| {name} | {} | {flips} | {off} | {:.2}% | {secs:.2} |",
        cloud.points.len(),
        100.0 * opposed
    );
}

/// `(flips, off)`: estimated normals opposed to the truth, and lines more than 18° apart.
fn errors(est: &[Point3], truth: &[Point3]) -> (usize, usize) {
    let cos18 = 18f64.to_radians().cos();
    let mut flips = 0;
    let mut off = 0;
    for (a, b) in est.iter().zip(truth) {
        let c = dot(*a, *b) / (norm(*a) * norm(*b)).max(f64::MIN_POSITIVE);
        flips += usize::from(c < 0.0);
        off += usize::from(c.abs() < cos18);
    }
    (flips, off)
}

/// Generated sets: the stock shapes at two densities, thin variants, noise, holes and range images.
fn generated() -> Vec<(String, PointCloud)> {
    let mut sets = Vec::new();
    for name in ["sphere", "torus", "two-spheres", "knot", "bumpy-sphere"] {
        let shape = Shape::by_name(name).expect("shape");
        for n in [2000, 20000] {
            sets.push((format!("{name} {n}"), shape.sample(n, 5)));
        }
    }
    let thin_torus = Shape::Torus {
        center: [0.5; 3],
        major: 0.35,
        minor: 0.02,
    };
    sets.push(("thin torus r=0.02 5000".into(), thin_torus.sample(5000, 6)));
    let touching = Shape::TwoSpheres {
        center: [0.5; 3],
        radius: 0.2,
        gap: 0.005,
    };
    sets.push((
        "two spheres gap 0.005 8000".into(),
        touching.sample(8000, 7),
    ));
    let sphere = Shape::by_name("sphere").expect("sphere");
    sets.push((
        "pancake 1:20 10000".into(),
        stretched(sphere.sample(10000, 8), [1.0, 1.0, 0.05]),
    ));
    sets.push((
        "needle 1:12 6000".into(),
        stretched(sphere.sample(6000, 9), [0.08, 0.08, 1.0]),
    ));
    let knot = Shape::by_name("knot").expect("knot");
    let defects = [
        ("noise 0.2%", noisy(0.002)),
        ("noise 0.5%", noisy(0.005)),
        (
            "6 holes",
            Defects {
                holes: 6,
                ..Defects::default()
            },
        ),
        (
            "range image +z",
            Defects {
                coverage: Coverage::RangeImage {
                    view: [0.3, 0.2, 1.0],
                },
                ..Defects::default()
            },
        ),
    ];
    for (label, d) in defects {
        for (name, shape) in [("torus", Shape::by_name("torus")), ("knot", Some(knot))] {
            let mut cloud = shape.expect("shape").sample(10000, 11);
            apply_defects(&mut cloud, &d, 3).expect("defects");
            sets.push((format!("{name} 10000 {label}"), cloud));
        }
    }
    sets
}

fn noisy(noise_rel: f64) -> Defects {
    Defects {
        noise_rel,
        ..Defects::default()
    }
}

/// Scale the points by `s` per axis about (0.5, 0.5, 0.5); normals transform by the inverse.
fn stretched(mut cloud: PointCloud, s: Point3) -> PointCloud {
    for p in &mut cloud.points {
        for k in 0..3 {
            p[k] = 0.5 + (p[k] - 0.5) * s[k];
        }
    }
    if let Some(normals) = cloud.normals.as_mut() {
        for n in normals.iter_mut() {
            let m = [n[0] / s[0], n[1] / s[1], n[2] / s[2]];
            let l = norm(m);
            *n = [m[0] / l, m[1] / l, m[2] / l];
        }
    }
    cloud
}
