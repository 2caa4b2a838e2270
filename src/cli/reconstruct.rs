//! `rbfsurf reconstruct INPUT -o OUT.{glb,ply,obj} [--report REPORT.json] [parameters]`.

use super::progress::BarProgress;
use crate::cli::outln;
use crate::io::{MeshFormat, ReadLimits};
use crate::params::{ReconOptions, ReconParams};
use crate::pipeline::{self, PointSource, RunOutput};
use anyhow::Result;
use std::path::PathBuf;

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
    /// Also write the fitted implicit function here (`.field`, see docs/volume-modelling.md; CSRBF
    /// only): operand of `rbfsurf csg`, `morph`, `voxelize`.
    #[arg(long, value_name = "FILE")]
    pub save_field: Option<PathBuf>,
    /// Reconstruction parameters.
    #[command(flatten)]
    pub options: ReconOptions,
    /// Refuse inputs with more points than this (default 50,000,000).
    #[arg(long)]
    pub max_points: Option<usize>,
    /// Run the out-of-core task graph even when the cloud fits the memory budget (the plan a
    /// cloud over the budget gets; what `rbfsurf worker` makes of a job it splits over idle
    /// workers, docs/distributed.md).
    #[arg(long)]
    pub out_of_core: bool,
    /// No progress bar (the result line is still printed, on standard output).
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: &ReconstructArgs) -> Result<()> {
    let params = ReconParams::try_from(&a.options)?;
    let glb = a.options.glb();
    let format = MeshFormat::from_path(&a.output)?.with_glb(glb);
    if glb.lods > 0 && !matches!(format, MeshFormat::Glb(_)) {
        anyhow::bail!("--lods needs a .glb output (got {})", a.output.display());
    }
    let outputs = [Some(&a.output), a.report.as_ref(), a.save_field.as_ref()];
    for out in outputs.into_iter().flatten() {
        super::check_parent(out)?;
    }
    let mut limits = ReadLimits {
        max_memory_mib: params.max_memory_mib,
        ..ReadLimits::default()
    };
    if let Some(m) = a.max_points {
        limits.max_points = m;
    }
    let output = RunOutput {
        mesh: &a.output,
        format,
        report: a.report.as_deref(),
        field: a.save_field.as_deref(),
        job_memory_mib: None,
    };
    let progress = BarProgress::new(a.quiet);
    let run = if a.out_of_core {
        pipeline::run_out_of_core
    } else {
        pipeline::run
    };
    let summary = run(
        PointSource::File(&a.input),
        &params,
        &limits,
        &output,
        &progress,
    );
    progress.finish();
    let report = summary?.report;
    let m = &report.mesh;
    // The result line is the command's output: `-q` hides the progress bar, not the result.
    outln!(
        "{} -> {}: {} points, {} triangles, {} component(s), watertight {}, genus {}, residual max {:.1e}, {:.2} s",
        a.input.display(),
        a.output.display(),
        report.input.used,
        m.triangles,
        m.components,
        m.watertight,
        m.genus_label(),
        report.residual.max,
        report.timings_s.total
    );
    for k in 1..=glb.lods {
        let p = crate::io::lod_path(&a.output, k);
        let lod = crate::io::glb_asset_extra(&std::fs::read(&p)?, "lod").unwrap_or_default();
        outln!(
            "  {}: {} triangles, simplification error {:.2e} ({:.2e} of the bbox diagonal)",
            p.display(),
            lod["triangles"],
            lod["error"].as_f64().unwrap_or(f64::NAN),
            lod["error_rel"].as_f64().unwrap_or(f64::NAN)
        );
    }
    Ok(())
}
