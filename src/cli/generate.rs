//! `rbfsurf generate SHAPE --points N -o OUT.ply`: synthetic clouds with analytic ground truth.

use crate::geometry::synthetic::Shape;
use anyhow::{Context, Result, bail};
use std::path::PathBuf;

/// Arguments of `generate`.
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Shape: sphere, torus or two-spheres (unit-cube sized).
    pub shape: String,
    /// Number of points.
    #[arg(long, default_value_t = 10_000)]
    pub points: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Translate every point by this amount along x, y and z (e.g. 1e6 to test far-from-origin data).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub offset: f64,
    /// Output PLY (binary) file.
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(a: &GenerateArgs) -> Result<()> {
    let Some(shape) = Shape::by_name(&a.shape) else {
        bail!(
            "unknown shape '{}': use sphere, torus or two-spheres",
            a.shape
        )
    };
    if a.points == 0 || a.points > 100_000_000 {
        bail!("--points {} is out of range 1..=100000000", a.points);
    }
    let mut cloud = shape.sample(a.points, a.seed);
    for p in &mut cloud.points {
        for v in p.iter_mut() {
            *v += a.offset;
        }
    }
    crate::io::write_points_ply(&a.output, &cloud)
        .with_context(|| format!("writing {}", a.output.display()))
}
