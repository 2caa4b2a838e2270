//! The two extractors side by side on fields fitted to real scans: uniform grid
//! (`Extraction::Uniform`, the pipeline's) against the adaptive two-level lattice
//! (`Extraction::Adaptive`), same field, same box, same resolution as the pipeline picks
//! (`auto_resolution`), runs interleaved in one process. Prints field values, triangles, the
//! topology and the best wall time of `REPEAT` runs (default 3) of each.
//!
//! Run with `cargo run --release --example extraction -- FILE...` (`TOL=x`: the adaptive
//! tolerance in point spacings, default 1).

use std::time::Instant;

use rbfsurf::geometry::Aabb;
use rbfsurf::mesh::analyze;
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::{auto_resolution, fit_field};
use rbfsurf::polygonize::{Extraction, PolygonizeParams, polygonize};
use rbfsurf::progress::NoProgress;
use rbfsurf::report::Timings;

fn main() {
    let tol: f64 = std::env::var("TOL").map_or(1.0, |v| v.parse().expect("TOL is a number"));
    let repeat: usize =
        std::env::var("REPEAT").map_or(3, |v| v.parse().expect("REPEAT is a count"));
    println!(
        "| input | extraction | field values | triangles | components | genus | watertight | best s |"
    );
    println!("|---|---|---:|---:|---:|---:|---|---:|");
    for path in std::env::args().skip(1) {
        let cloud = match rbfsurf::io::read_point_cloud(path.as_ref(), &Default::default()) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("{path}: {e}");
                continue;
            }
        };
        let fit = fit_field(
            &cloud,
            &ReconParams::default(),
            &NoProgress,
            &mut Timings::default(),
        )
        .expect("fit");
        let resolution = auto_resolution(fit.support.spacing);
        let b = Aabb::from_points(&fit.points);
        let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
        let domain = b.inflated(fit.support_radius + 3.0 * longest / resolution as f64);
        let kinds = [
            ("uniform", Extraction::Uniform),
            (
                "adaptive",
                Extraction::Adaptive {
                    tolerance: tol * fit.support.spacing,
                },
            ),
        ];
        let mut best = [f64::INFINITY; 2];
        let mut last = Vec::new();
        for _ in 0..repeat {
            last.clear();
            for (k, (_, extraction)) in kinds.iter().enumerate() {
                let params = PolygonizeParams {
                    resolution,
                    extraction: *extraction,
                    ..Default::default()
                };
                let t = Instant::now();
                let out = polygonize(fit.field.as_ref(), &domain, &params, &NoProgress)
                    .expect("polygonize");
                best[k] = best[k].min(t.elapsed().as_secs_f64());
                last.push(out);
            }
        }
        let name = std::path::Path::new(&path)
            .file_name()
            .map_or(path.clone(), |n| n.to_string_lossy().into_owned());
        for (k, (mesh, stats)) in last.iter().enumerate() {
            let t = analyze(mesh);
            println!(
                "| {name} | {} | {} | {} | {} | {} | {} | {:.3} |",
                kinds[k].0,
                stats.field_evaluations,
                mesh.triangles.len(),
                t.components,
                t.genus.map_or("-".into(), |g| g.to_string()),
                t.watertight,
                best[k]
            );
        }
    }
}
