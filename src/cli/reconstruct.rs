//! `rbfsurf reconstruct INPUT -o OUT.{glb,ply,obj} [--report REPORT.json] [parameters]`.

use super::progress::BarProgress;
use crate::io::{MeshFormat, ReadLimits, read_point_cloud, write_atomic, write_mesh};
use crate::linalg::SolverKind;
use crate::ordering::OrderingKind;
use crate::params::{Polynomial, ReconParams};
use crate::progress::Progress;
use crate::rbf::{CarrierKind, Kernel, Support};
use crate::spatial::IndexKind;
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `reconstruct`. Every parameter is optional: `None` takes the library default.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ReconstructArgs {
    /// Input point file: PLY (ascii/binary), XYZ/PTS/CSV text (3 or 6 columns), OBJ vertices.
    pub input: PathBuf,
    /// Output mesh: .glb, .ply or .obj (written to a temporary file, then renamed).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Kernel: wendland-c0 (seed), wendland-c2 (default), wendland-c4.
    #[arg(long)]
    pub kernel: Option<Kernel>,
    /// Support radius R in normalised units (the longest bbox edge is 1).
    #[arg(long, conflicts_with = "neighbours", allow_negative_numbers = true)]
    pub support: Option<f64>,
    /// Choose R to give about K neighbours per point (default 30).
    #[arg(long)]
    pub neighbours: Option<usize>,
    /// Carrier solid: auto (default), sphere, ellipsoid, local.
    #[arg(long)]
    pub carrier: Option<CarrierKind>,
    /// Matrix ordering: none, bfs (seed Algorithm III), rcm (default).
    #[arg(long)]
    pub ordering: Option<OrderingKind>,
    /// Solver: sparse (default, faer supernodal Cholesky + AMD), envelope (own Jennings profile Cholesky), ldl (sprs-ldl).
    #[arg(long)]
    pub solver: Option<SolverKind>,
    /// Polynomial part: none (default) or linear (doubly bordered system).
    #[arg(long)]
    pub polynomial: Option<Polynomial>,
    /// Marching grid cells along the longest axis (default: from the point spacing, 64..320).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// Spatial index: octree or kdtree.
    #[arg(long)]
    pub index: Option<IndexKind>,
    /// Octree leaf size K.
    #[arg(long)]
    pub leaf_size: Option<usize>,
    /// Merge points closer than this fraction of the bbox diagonal (default 1e-6).
    #[arg(long)]
    pub merge_tolerance: Option<f64>,
    /// Memory budget for matrix + factor in MiB (default 8192); bigger systems are refused up front.
    #[arg(long)]
    pub max_memory_mib: Option<u64>,
    /// Refuse inputs with more points than this (default 50,000,000).
    #[arg(long)]
    pub max_points: Option<usize>,
    /// No progress bar.
    #[arg(short, long)]
    pub quiet: bool,
}

impl TryFrom<&ReconstructArgs> for ReconParams {
    type Error = crate::params::ParamError;
    fn try_from(a: &ReconstructArgs) -> Result<Self, Self::Error> {
        let mut p = ReconParams::default();
        if let Some(k) = a.kernel {
            p.kernel = k;
        }
        if let Some(r) = a.support {
            p.support = Support::Radius(r);
        }
        if let Some(k) = a.neighbours {
            p.support = Support::Neighbours(k);
        }
        if let Some(c) = a.carrier {
            p.carrier.kind = c;
        }
        if let Some(o) = a.ordering {
            p.ordering = o;
        }
        if let Some(s) = a.solver {
            p.solver = s;
        }
        if let Some(poly) = a.polynomial {
            p.polynomial = poly;
        }
        p.resolution = a.resolution.or(p.resolution);
        if let Some(i) = a.index {
            p.index = i;
        }
        if let Some(l) = a.leaf_size {
            p.leaf_size = l;
        }
        if let Some(t) = a.merge_tolerance {
            p.clean.merge_tolerance = t;
        }
        if let Some(m) = a.max_memory_mib {
            p.max_memory_mib = m;
        }
        p.validate()?;
        Ok(p)
    }
}

pub fn run(a: &ReconstructArgs) -> Result<()> {
    let start = Instant::now();
    let params = ReconParams::try_from(a)?;
    let format = MeshFormat::from_path(&a.output)?;
    for out in std::iter::once(&a.output).chain(a.report.as_ref()) {
        let dir = out.parent().filter(|d| !d.as_os_str().is_empty());
        if let Some(d) = dir
            && !d.is_dir()
        {
            bail!(
                "{}: the output directory {} does not exist",
                out.display(),
                d.display()
            );
        }
    }
    let input = a.input.display().to_string();
    let progress = BarProgress::new(a.quiet);
    let t = Instant::now();
    let mut limits = ReadLimits::default();
    if let Some(m) = a.max_points {
        limits.max_points = m;
    }
    let cloud = read_point_cloud(&a.input, &limits)?;
    let read_s = t.elapsed().as_secs_f64();
    let mut rec = crate::reconstruct(&cloud, &params, &progress).with_context(|| input.clone())?;
    drop(cloud);
    progress.stage("write");
    let t = Instant::now();
    write_mesh(&a.output, &rec.mesh, format)?;
    rec.report.timings_s.read = read_s;
    rec.report.timings_s.write = t.elapsed().as_secs_f64();
    rec.report.timings_s.total = start.elapsed().as_secs_f64();
    rec.report.memory.peak_rss_mib = crate::report::peak_rss_mib();
    progress.finish();
    if let Some(path) = &a.report {
        let json = serde_json::to_vec_pretty(&rec.report)?;
        write_atomic(path, &json)?;
    }
    if !a.quiet {
        let m = &rec.report.mesh;
        eprintln!(
            "{} -> {}: {} points, {} triangles, {} component(s), watertight {}, genus {}, residual max {:.1e}, {:.2} s",
            input,
            a.output.display(),
            rec.report.input.used,
            m.triangles,
            m.components,
            m.watertight,
            m.genus.map_or("-".to_string(), |g| g.to_string()),
            rec.report.residual.max,
            rec.report.timings_s.total
        );
    }
    Ok(())
}
