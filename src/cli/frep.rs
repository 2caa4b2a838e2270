//! Volume modelling commands: `field info`, `csg`, `morph`, `voxelize` (see docs/volume-modelling.md).

use super::check_parent;
use super::progress::BarProgress;
use crate::cli::outln;
use crate::frep::expr::{Loader, build};
use crate::frep::{Align, CsgParams, MorphParams, Solid, VoxelParams, format, parse};
use crate::io::{
    GlbCompression, GlbOptions, MeshFormat, encode_animated_glb, write_atomic, write_mesh,
};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `rbfsurf field …`.
#[derive(Debug, Clone, clap::Args)]
pub struct FieldArgs {
    /// What to do with the field file.
    #[command(subcommand)]
    pub command: FieldCommand,
}

/// Subcommands of `field`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum FieldCommand {
    /// Print a field file's header, sizes and bounds as JSON.
    Info {
        /// A `.field` file written by `reconstruct --save-field`.
        file: PathBuf,
    },
}

/// Arguments of `csg`.
#[derive(Debug, Clone, clap::Args)]
pub struct CsgArgs {
    /// The expression, e.g. "difference(out/kitten.field, sphere(0, 0, 0.5, 0.3))".
    pub expression: String,
    /// Output mesh: .glb, .ply or .obj.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Grid cells along the longest edge of the result's box (default 160).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// No progress bar.
    #[arg(short, long)]
    pub quiet: bool,
    /// GLB storage: meshopt (default: quantized + meshopt-compressed) or none (plain float glTF).
    #[arg(long, default_value_t = GlbCompression::Meshopt)]
    pub glb_compression: GlbCompression,
}

/// Arguments of `morph`.
#[derive(Debug, Clone, clap::Args)]
pub struct MorphArgs {
    /// The start: a field file or an expression.
    pub a: String,
    /// The end: a field file or an expression (aligned to the start first).
    pub b: String,
    /// Frames including both ends (2..=256).
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Output directory (created): frame_000.glb …, morph.glb (animated), report.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// A field or expression no frame may enter.
    #[arg(long)]
    pub obstacle: Option<String>,
    /// Alignment of B to A: bbox (default), pca, none.
    #[arg(long, default_value = "bbox")]
    pub align: String,
    /// A user map from A's space to B's instead: 12 numbers "m00 m01 m02 t0 m10 … t2".
    #[arg(long)]
    pub affine: Option<String>,
    /// Grid cells along the longest edge (default 128).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// Seconds each frame shows in morph.glb.
    #[arg(long, default_value_t = 0.25)]
    pub seconds_per_frame: f32,
    /// GLB storage of the frame_NNN.glb files: meshopt (default) or none (plain float glTF);
    /// morph.glb (the animation) is always plain float glTF.
    #[arg(long, default_value_t = GlbCompression::Meshopt)]
    pub glb_compression: GlbCompression,
}

/// Arguments of `voxelize`.
#[derive(Debug, Clone, clap::Args)]
pub struct VoxelizeArgs {
    /// A field file or an expression.
    pub input: String,
    /// Samples along the longest edge (2..=1024).
    #[arg(long, default_value_t = 128)]
    pub resolution: usize,
    /// Output volume: .vti (VTK XML ImageData) or .nrrd.
    #[arg(short, long)]
    pub output: PathBuf,
}

fn solid_of(src: &str, loader: &mut Loader) -> Result<Solid> {
    Ok(build(&parse(src)?, loader)?)
}

/// `field info`.
pub fn run_field(a: &FieldArgs) -> Result<()> {
    let FieldCommand::Info { file } = &a.command;
    let t = Instant::now();
    let model = format::read(file)?;
    let bytes = std::fs::metadata(file).map(|m| m.len()).unwrap_or(0);
    let mut info = format::info(&model, bytes);
    info["load_seconds"] = serde_json::json!(t.elapsed().as_secs_f64());
    outln!("{}", serde_json::to_string_pretty(&info)?);
    Ok(())
}

/// `csg`.
pub fn run_csg(a: &CsgArgs) -> Result<()> {
    let start = Instant::now();
    let format =
        MeshFormat::from_path(&a.output)?.with_glb(GlbOptions::compressed(a.glb_compression));
    for out in std::iter::once(&a.output).chain(a.report.as_ref()) {
        check_parent(out)?;
    }
    let solid = solid_of(&a.expression, &mut Loader::new(Path::new(".")))?;
    let load = start.elapsed().as_secs_f64();
    let params = CsgParams {
        resolution: a.resolution.unwrap_or(CsgParams::default().resolution),
        ..Default::default()
    };
    if params.resolution < 8 {
        bail!(
            "invalid parameter resolution = {}: at least 8 cells",
            params.resolution
        );
    }
    let progress = BarProgress::new(a.quiet);
    let result = crate::frep::mesh_solid(&solid, &a.expression, &params, &progress);
    progress.finish();
    let (mesh, mut report) = result?;
    write_mesh(&a.output, &mesh, format)?;
    report.timings_s.load = load;
    report.timings_s.total = start.elapsed().as_secs_f64();
    if let Some(path) = &a.report
        && let Err(e) = write_atomic(path, &serde_json::to_vec_pretty(&report)?)
    {
        let _ = std::fs::remove_file(&a.output);
        return Err(e.into());
    }
    let m = &report.mesh;
    outln!(
        "{} -> {}: {} triangles, {} component(s), watertight {}, genus {}, {}/{} blocks evaluated, {:.2} s",
        a.expression,
        a.output.display(),
        m.triangles,
        m.components,
        m.watertight,
        m.genus_label(),
        report.blocks_active,
        report.blocks_total,
        report.timings_s.total
    );
    Ok(())
}

fn parse_align(a: &MorphArgs) -> Result<Align> {
    if let Some(s) = &a.affine {
        let v: Vec<f64> = s
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
            .map(|t| {
                t.parse::<f64>()
                    .with_context(|| format!("--affine: '{t}' is not a number"))
            })
            .collect::<Result<_>>()?;
        if v.len() != 12 || v.iter().any(|x| !x.is_finite()) {
            bail!(
                "--affine takes 12 finite numbers (3 rows of m0 m1 m2 t), got {}",
                v.len()
            );
        }
        return Ok(Align::Affine(
            [0, 1, 2].map(|i| [0, 1, 2, 3].map(|j| v[4 * i + j])),
        ));
    }
    Ok(match a.align.as_str() {
        "bbox" => Align::BoundingBox,
        "pca" => Align::Pca,
        "none" => Align::None,
        other => bail!("unknown --align '{other}' (use bbox, pca or none)"),
    })
}

/// `morph`.
pub fn run_morph(a: &MorphArgs) -> Result<()> {
    let align = parse_align(a)?;
    if a.output.exists() && !a.output.is_dir() {
        bail!("{}: exists and is not a directory", a.output.display());
    }
    check_parent(&a.output)?;
    let mut loader = Loader::new(Path::new("."));
    let sa = solid_of(&a.a, &mut loader)?;
    let sb = solid_of(&a.b, &mut loader)?;
    let obstacle = a
        .obstacle
        .as_deref()
        .map(|o| solid_of(o, &mut loader))
        .transpose()?;
    let params = MorphParams {
        frames: a.frames,
        mesh: CsgParams {
            resolution: a.resolution.unwrap_or(128),
            ..Default::default()
        },
        align,
    };
    let progress = BarProgress::new(false);
    let mut frames = Vec::with_capacity(a.frames);
    let result = crate::frep::morph(sa, sb, obstacle, &params, &progress, |_, m| {
        frames.push(m);
        Ok(())
    });
    progress.finish();
    let report = result?;
    let anim = encode_animated_glb(&frames, a.seconds_per_frame)?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("{}: cannot create the directory", a.output.display()))?;
    let mut written: Vec<PathBuf> = Vec::new();
    let mut write_all = || -> Result<()> {
        for (i, m) in frames.iter().enumerate() {
            let p = a.output.join(format!("frame_{i:03}.glb"));
            write_mesh(
                &p,
                m,
                MeshFormat::Glb(GlbOptions::compressed(a.glb_compression)),
            )?;
            written.push(p);
        }
        let p = a.output.join("morph.glb");
        write_atomic(&p, &anim)?;
        written.push(p);
        let p = a.output.join("report.json");
        write_atomic(&p, &serde_json::to_vec_pretty(&report)?)?;
        Ok(())
    };
    if let Err(e) = write_all() {
        written.iter().for_each(|p| {
            let _ = std::fs::remove_file(p);
        });
        return Err(e);
    }
    for f in &report.frames {
        outln!(
            "t={:.3}: {} triangles, {} component(s), watertight {}, genus {}",
            f.t,
            f.triangles,
            f.components,
            f.watertight,
            f.genus.map_or("-".to_string(), |g| g.to_string())
        );
    }
    outln!(
        "{} frames -> {} ({:.2} s)",
        report.frames.len(),
        a.output.display(),
        report.seconds
    );
    Ok(())
}

/// `voxelize`.
pub fn run_voxelize(a: &VoxelizeArgs) -> Result<()> {
    check_parent(&a.output)?;
    let t = Instant::now();
    let solid = solid_of(&a.input, &mut Loader::new(Path::new(".")))?;
    let grid = crate::frep::voxelize(
        &solid,
        &VoxelParams {
            resolution: a.resolution,
        },
    )?;
    crate::frep::voxel::write_volume(&a.output, &grid)?;
    outln!(
        "{} -> {}: {}×{}×{} samples, spacing {:.4e}, origin {:?}, {:.2} s",
        a.input,
        a.output.display(),
        grid.dims[0],
        grid.dims[1],
        grid.dims[2],
        grid.spacing,
        grid.origin,
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
