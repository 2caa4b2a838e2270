//! `rbfsurf generate SHAPE --points N -o OUT.ply`: synthetic clouds with analytic ground truth, the
//! defects of real scans (noise, outliers, holes, one range image, no normals) and a truth mesh.

use crate::geometry::synthetic::{Coverage, Defects, SHAPE_NAMES, Shape, apply_defects};
use crate::io::MeshFormat;
use anyhow::{Context, Result, bail};
use std::path::PathBuf;

/// Triangles of the truth mesh written by `--truth` (its chordal error is then ≲ 2e-5 of the
/// bounding-box diagonal for every shape, far below the noise levels of interest).
const TRUTH_TRIANGLES: usize = 400_000;

/// Arguments of `generate`.
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Shape: sphere, torus, two-spheres, knot (trefoil tube, genus 1) or bumpy-sphere (unit-cube sized).
    pub shape: String,
    /// Number of points sampled (before --open and --holes remove some).
    #[arg(long, default_value_t = 10_000)]
    pub points: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Gaussian noise: each point moves by σ·g along a random direction, σ = F × bbox diagonal (e.g. 0.001).
    #[arg(long, value_name = "F", default_value_t = 0.0)]
    pub noise: f64,
    /// Replace this fraction of the points by uniform points in the bbox grown by 10% (random normals).
    #[arg(long, value_name = "F", default_value_t = 0.0)]
    pub outliers: f64,
    /// Remove all points within 0.08 × bbox diagonal of K random sample points.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub holes: usize,
    /// Keep only the points facing +z (one range image; an open surface).
    #[arg(long)]
    pub open: bool,
    /// Write the points without normals.
    #[arg(long)]
    pub no_normals: bool,
    /// Translate every point by this amount along x, y and z (e.g. 1e6 to test far-from-origin data).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub offset: f64,
    /// Also write the closed truth mesh (~400k triangles, offset applied) here: .ply is f32, .glb
    /// 16-bit quantized (error below 1.3e-5 of the longest bbox edge; f32 with
    /// --glb-compression none), use .obj for full precision with large --offset.
    #[arg(long, value_name = "OUT_TRUTH")]
    pub truth: Option<PathBuf>,
    /// GLB storage of a .glb truth mesh: meshopt (default: quantized + meshopt-compressed) or none
    /// (plain float glTF).
    #[arg(long, default_value_t = crate::io::GlbCompression::Meshopt)]
    pub glb_compression: crate::io::GlbCompression,
    /// Output PLY (binary) file.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(a: &GenerateArgs) -> Result<()> {
    let Some(shape) = Shape::by_name(&a.shape) else {
        bail!(
            "unknown shape '{}': use one of {}",
            a.shape,
            SHAPE_NAMES.join(", ")
        )
    };
    if a.points == 0 || a.points > 100_000_000 {
        bail!("--points {} is out of range 1..=100000000", a.points);
    }
    let truth_format = match &a.truth {
        Some(p) => {
            let glb = crate::io::GlbOptions::compressed(a.glb_compression);
            let f = MeshFormat::from_path(p).with_context(|| format!("--truth {}", p.display()))?;
            Some(f.with_glb(glb))
        }
        None => None,
    };
    let mut cloud = shape.sample(a.points, a.seed);
    let defects = Defects {
        coverage: if a.open {
            Coverage::RangeImage {
                view: [0.0, 0.0, 1.0],
            }
        } else {
            Coverage::Full
        },
        holes: a.holes,
        noise_rel: a.noise,
        outlier_fraction: a.outliers,
        ..Defects::default()
    };
    apply_defects(&mut cloud, &defects, a.seed).context("--noise / --outliers / --holes")?;
    if cloud.points.is_empty() {
        bail!("no points are left after --holes/--open: use fewer holes or more points");
    }
    if a.no_normals {
        cloud.normals = None;
    }
    offset_points(&mut cloud.points, a.offset);
    crate::io::write_points_ply(&a.output, &cloud)
        .with_context(|| format!("writing {}", a.output.display()))?;
    if let (Some(path), Some(format)) = (&a.truth, truth_format) {
        let resolution = (8..=100_000)
            .find(|&r| shape.truth_triangles(r) >= TRUTH_TRIANGLES)
            .unwrap_or(100_000);
        let mut mesh = shape.truth_mesh(resolution);
        offset_points(&mut mesh.vertices, a.offset);
        crate::io::write_mesh(path, &mesh, format)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn offset_points(points: &mut [[f64; 3]], offset: f64) {
    if offset != 0.0 {
        for p in points {
            for v in p.iter_mut() {
                *v += offset;
            }
        }
    }
}
