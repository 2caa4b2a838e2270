//! The command line: `reconstruct`, `compare`, `generate`, `bench`, `serve`, `submit`, `openapi`. Parses arguments, calls the
//! library, prints one-line errors. No numerical code lives here.

mod bench;
mod compare;
mod curve;
mod frep;
mod generate;
mod http;
pub(crate) mod progress;
mod reconstruct;
#[cfg(feature = "server")]
mod serve;
mod submit;
#[cfg(feature = "nats")]
mod worker;

use clap::{Parser, Subcommand};

/// `println!` for command output that a closed pipe (`rbfsurf compare … | head -1`) ends quietly
/// with exit code 0 instead of a panic; other stdout errors are reported on stderr with exit 1.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($arg)*) {
            $crate::cli::stdout_failed(e);
        }
    }};
}
pub(crate) use outln;

/// Exit on a failed write to stdout: quietly for a closed pipe, with a message otherwise.
pub(crate) fn stdout_failed(e: std::io::Error) -> ! {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    eprintln!("rbfsurf: error: writing to standard output: {e}");
    std::process::exit(1);
}

/// rbfsurf: watertight meshes from point clouds with compactly supported RBFs.
#[derive(Debug, Parser)]
#[command(name = "rbfsurf", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Reconstruct a mesh from a point file (PLY, XYZ/PTS/CSV, OBJ) and write GLB/PLY/OBJ.
    Reconstruct(reconstruct::ReconstructArgs),
    /// Accuracy of a mesh against a reference mesh or point set (Chamfer, Hausdorff, relative to the reference's bbox diagonal).
    Compare(compare::CompareArgs),
    /// Write a synthetic point set as PLY (sphere, torus, two-spheres, knot, bumpy-sphere; normals unless --no-normals; optional noise, outliers, holes, truth mesh).
    Generate(generate::GenerateArgs),
    /// 2D implicit curves workbench: fit constraints (x y [nx ny] [value]) and write an SVG + JSON report.
    Curve(curve::CurveArgs),
    /// Inspect a saved field (`reconstruct --save-field`): `field info FILE`.
    Field(frep::FieldArgs),
    /// Mesh an expression over saved fields and primitives (union, intersection, difference, blend, offset, …).
    Csg(frep::CsgArgs),
    /// Metamorphosis A → B: meshed frames with their topology, an animated GLB and a report.
    Morph(frep::MorphArgs),
    /// Sample a field or expression on a grid: VTK XML ImageData (.vti) or NRRD, float32, F >= 0 inside.
    Voxelize(frep::VoxelizeArgs),
    /// Run a benchmark and print a table (`table1`: the seed's Table 1; `scaling`: N = 10k..300k).
    Bench(bench::BenchArgs),
    /// Run the HTTP service: REST API, job queue, WebGL viewer at `/`.
    #[cfg(feature = "server")]
    Serve(serve::ServeArgs),
    /// Upload a point file to a running server, wait, download the mesh (non-zero exit on failure).
    Submit(submit::SubmitArgs),
    /// Pull and run reconstruction tasks from NATS JetStream (the workers of `serve --nats`).
    #[cfg(feature = "nats")]
    Worker(worker::WorkerArgs),
    /// Print the OpenAPI document of the HTTP API.
    #[cfg(feature = "server")]
    Openapi(serve::OpenApiArgs),
}

/// Run the command line with these arguments (the first is the program name); returns the exit code.
pub fn run<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) if !e.use_stderr() => {
            let _ = e.print();
            return 0;
        }
        Err(e) => {
            // One line: clap's first line, without its usage block.
            let text = e.render().to_string();
            let first = text
                .lines()
                .next()
                .unwrap_or("invalid arguments")
                .trim_start_matches("error: ");
            eprintln!("rbfsurf: error: {first} (see rbfsurf --help)");
            return 2;
        }
    };
    let result = match cli.command {
        Command::Reconstruct(a) => reconstruct::run(&a),
        Command::Compare(a) => compare::run(&a),
        Command::Generate(a) => generate::run(&a),
        Command::Bench(a) => bench::run(&a),
        Command::Field(a) => frep::run_field(&a),
        Command::Csg(a) => frep::run_csg(&a),
        Command::Morph(a) => frep::run_morph(&a),
        Command::Voxelize(a) => frep::run_voxelize(&a),
        Command::Curve(a) => curve::run(&a),
        #[cfg(feature = "server")]
        Command::Serve(a) => serve::run(&a),
        Command::Submit(a) => submit::run(&a),
        #[cfg(feature = "nats")]
        Command::Worker(a) => worker::run(&a),
        #[cfg(feature = "server")]
        Command::Openapi(a) => serve::run_openapi(&a),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("rbfsurf: error: {}", one_line(&e));
            1
        }
    }
}

/// The error and its causes on one line, each cause once (a stage error that already quotes its
/// OS error does not get it appended again).
fn one_line(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !msg.contains(&text) {
            if !msg.is_empty() {
                msg.push_str(": ");
            }
            msg.push_str(&text);
        }
    }
    msg.replace('\n', " ")
}

/// Refuse an output path whose directory does not exist (before any work is done).
fn check_parent(out: &std::path::Path) -> anyhow::Result<()> {
    let dir = out.parent().filter(|d| !d.as_os_str().is_empty());
    if let Some(d) = dir
        && !d.is_dir()
    {
        anyhow::bail!(
            "{}: the output directory {} does not exist",
            out.display(),
            d.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    /// The flags of `reconstruct` as a markdown table, from the same definitions that give
    /// `--help` and the OpenAPI parameter descriptions.
    fn reconstruct_flags_markdown() -> String {
        let cmd = Cli::command();
        let rec = cmd.find_subcommand("reconstruct").expect("reconstruct");
        let mut out =
            String::from("| flag | meaning (from `rbfsurf reconstruct --help`) |\n|---|---|\n");
        for arg in rec.get_arguments() {
            let Some(long) = arg.get_long() else { continue };
            let help = arg.get_help().map(|h| h.to_string()).unwrap_or_default();
            let value = match arg.get_action().takes_values() {
                true => format!(
                    " {}",
                    arg.get_id().as_str().to_uppercase().replace('_', "-")
                ),
                false => String::new(),
            };
            out.push_str(&format!(
                "| `--{long}{value}` | {} |\n",
                help.replace('|', "\\|")
            ));
        }
        out
    }

    /// docs/parameters.md carries the generated flag table between markers: help texts and the
    /// docs cannot drift. `UPDATE_DOCS=1 cargo test --lib cli::` rewrites it.
    #[test]
    fn docs_parameter_table_matches_the_help_texts() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/parameters.md");
        let doc = std::fs::read_to_string(&path).expect("docs/parameters.md");
        let (begin, end) = (
            "<!-- BEGIN generated flags -->\n",
            "<!-- END generated flags -->",
        );
        let (a, b) = (
            doc.find(begin).expect("begin marker") + begin.len(),
            doc.find(end).expect("end marker"),
        );
        let want = reconstruct_flags_markdown();
        if std::env::var_os("UPDATE_DOCS").is_some() {
            let new = format!("{}{}{}", &doc[..a], want, &doc[b..]);
            std::fs::write(&path, new).unwrap();
            return;
        }
        assert_eq!(
            &doc[a..b],
            want,
            "docs/parameters.md is out of date: run UPDATE_DOCS=1 cargo test --lib cli::"
        );
    }
}
