//! `rbfsurf reconstruct INPUT -o OUT.{glb,ply,obj} [--report REPORT.json] [parameters]`.

use super::progress::BarProgress;
use crate::io::{
    MeshFormat, ReadLimits, peek_point_count, read_point_cloud, write_atomic, write_mesh,
};
use crate::params::{ReconOptions, ReconParams};
use crate::progress::Progress;
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
    /// Reconstruction parameters.
    #[command(flatten)]
    pub options: ReconOptions,
    /// Refuse inputs with more points than this (default 50,000,000).
    #[arg(long)]
    pub max_points: Option<usize>,
    /// No progress bar.
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: &ReconstructArgs) -> Result<()> {
    let start = Instant::now();
    let params = ReconParams::try_from(&a.options)?;
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
    let mut limits = ReadLimits {
        max_memory_mib: params.max_memory_mib,
        ..ReadLimits::default()
    };
    if let Some(m) = a.max_points {
        limits.max_points = m;
    }
    // Refuse a scan whose points alone cannot fit the memory budget before reading it.
    let hint = peek_point_count(&a.input)?;
    hint.check_budget(&limits, &a.input)?;
    crate::pipeline::check_scale(hint.points, params.max_memory_mib)
        .with_context(|| input.clone())?;
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
