//! `rbfsurf curve`: the 2D curves workbench (a thin adapter over
//! [`crate::variational::run_workbench`]).

use std::path::PathBuf;

use anyhow::Context;

use crate::variational::{
    CurveMethod, CurveParams, Offset, WeightPower, curve_io, datasets, run_workbench,
    run_workbench_incremental,
};

/// Fitting method names on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodArg {
    /// Turk–O'Brien with pseudo-normal points.
    TurkObrien,
    /// Turk–O'Brien with true normals (gradient constraints).
    TurkObrienNormals,
    /// Turk–O'Brien with Mann's three-solve true normals.
    TurkObrienMann,
    /// Shen MLS, constant, pseudo-normals.
    ShenConstant,
    /// Shen MLS, linear, pseudo-normals.
    ShenLinear,
    /// Shen MLS, constant, true normals.
    ShenConstantNormals,
    /// Shen MLS, linear, true normals.
    ShenLinearNormals,
}

/// Arguments of `rbfsurf curve`.
#[derive(Debug, clap::Args)]
pub struct CurveArgs {
    /// Input text file (`x y [nx ny] [value]` per line, `#` comments); omit with --dataset.
    pub input: Option<PathBuf>,
    /// Output SVG.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
    /// Fitting method.
    #[arg(long, value_enum, default_value_t = MethodArg::TurkObrien)]
    pub method: MethodArg,
    /// Marching-squares cells along the longer side.
    #[arg(long, default_value_t = 200)]
    pub grid: usize,
    /// Shen's ε in normalised units (0 interpolates).
    #[arg(long, default_value_t = 0.0)]
    pub epsilon: f64,
    /// Pseudo-normal offset as a fraction of the median point spacing.
    #[arg(long, default_value_t = 0.1)]
    pub offset: f64,
    /// Margin around the data as a fraction of its size.
    #[arg(long, default_value_t = 0.25)]
    pub margin: f64,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Use a built-in data set instead of a file (shen27, koch0..koch4, square, ...).
    #[arg(long)]
    pub dataset: Option<String>,
    /// Add the constraints of this second file (same format) to the solved system by a
    /// Schur-complement update instead of refitting (turk-obrien only); the report's
    /// `incremental` object gives the update time, a fresh solve's time and their difference.
    #[arg(long)]
    pub add: Option<PathBuf>,
}

fn read_samples(path: &std::path::Path) -> anyhow::Result<Lines> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    curve_io::parse_curve_lines(&text).with_context(|| format!("in {}", path.display()))
}

/// Samples of a curve file with the 1-based file line of each.
type Lines = (Vec<crate::variational::Sample<2>>, Vec<usize>);

/// Name the file lines of the rows an error mentions.
fn with_lines(
    e: crate::variational::VariationalError,
    path: &std::path::Path,
    lines: &[usize],
) -> anyhow::Error {
    let named: Vec<String> = e
        .rows()
        .iter()
        .filter_map(|&r| lines.get(r).map(|l| format!("row {r} = line {l}")))
        .collect();
    let msg = if named.is_empty() {
        format!("in {}", path.display())
    } else {
        format!("in {} ({})", path.display(), named.join(", "))
    };
    anyhow::Error::new(e).context(msg)
}

/// Run the workbench and write the SVG (and report) atomically.
pub fn run(a: &CurveArgs) -> anyhow::Result<()> {
    let (samples, lines) = match (&a.dataset, &a.input) {
        (Some(name), None) => (datasets::by_name(name)?, Vec::new()),
        (None, Some(path)) => read_samples(path)?,
        _ => anyhow::bail!("give either an input file or --dataset NAME (not both)"),
    };
    let method = match a.method {
        MethodArg::TurkObrien => CurveMethod::TurkObrien,
        MethodArg::TurkObrienNormals => CurveMethod::TurkObrienNormals,
        MethodArg::TurkObrienMann => CurveMethod::TurkObrienMann,
        MethodArg::ShenConstant => CurveMethod::ShenConstant,
        MethodArg::ShenLinear => CurveMethod::ShenLinear,
        MethodArg::ShenConstantNormals => CurveMethod::ShenConstantNormals,
        MethodArg::ShenLinearNormals => CurveMethod::ShenLinearNormals,
    };
    let params = CurveParams {
        method,
        grid: a.grid,
        epsilon: a.epsilon,
        weight: WeightPower::Auto,
        offset: Offset::SpacingFraction(a.offset),
        margin: a.margin,
        ..Default::default()
    };
    let out = match &a.add {
        None => run_workbench(&samples, &params).map_err(|e| match &a.input {
            Some(p) => with_lines(e, p, &lines),
            None => e.into(),
        })?,
        Some(path) => {
            let (extra, _) = read_samples(path)?;
            run_workbench_incremental(&samples, &extra, &params)
                .with_context(|| format!("adding the constraints of {}", path.display()))?
        }
    };
    write_atomic(&a.output, out.svg.as_bytes())?;
    if let Some(r) = &a.report {
        write_atomic(r, serde_json::to_string_pretty(&out.report)?.as_bytes())?;
    }
    Ok(())
}

fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("cannot write in {}", dir.display()))?;
    std::io::Write::write_all(&mut tmp, bytes)?;
    tmp.persist(path)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dataset_to_svg_and_report() {
        let dir = tempfile::tempdir().unwrap();
        let a = CurveArgs {
            input: None,
            output: dir.path().join("k.svg"),
            method: MethodArg::ShenLinearNormals,
            grid: 60,
            epsilon: 0.0,
            offset: 0.1,
            margin: 0.25,
            report: Some(dir.path().join("k.json")),
            dataset: Some("koch1".into()),
            add: None,
        };
        run(&a).unwrap();
        assert!(
            std::fs::read_to_string(&a.output)
                .unwrap()
                .starts_with("<svg")
        );
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("k.json")).unwrap())
                .unwrap();
        assert_eq!(j["quality"]["components"], 1);
        let bad = CurveArgs {
            dataset: Some("nope".into()),
            ..a
        };
        assert!(
            run(&bad)
                .unwrap_err()
                .to_string()
                .contains("unknown data set")
        );
    }

    #[test]
    fn errors_name_file_lines() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("bad.txt");
        // Data rows 0..3; row 3 (file line 6) has a NaN.
        std::fs::write(&input, "# header\n0 0\n\n1 0\n1 1\nnan 1\n").unwrap();
        let a = CurveArgs {
            input: Some(input),
            output: dir.path().join("b.svg"),
            method: MethodArg::TurkObrien,
            grid: 40,
            epsilon: 0.0,
            offset: 0.1,
            margin: 0.25,
            report: None,
            dataset: None,
            add: None,
        };
        let msg = format!("{:#}", run(&a).unwrap_err());
        assert!(msg.contains("row 3 = line 6"), "{msg}");
    }

    #[test]
    fn add_updates_incrementally_and_reports() {
        let dir = tempfile::tempdir().unwrap();
        let (base, extra) = (dir.path().join("base.txt"), dir.path().join("extra.txt"));
        let ring = |n: usize, r: f64, phase: f64| {
            (0..n)
                .map(|k| {
                    let t = phase + k as f64 * std::f64::consts::TAU / n as f64;
                    format!("{} {} {} {}\n", r * t.cos(), r * t.sin(), t.cos(), t.sin())
                })
                .collect::<String>()
        };
        std::fs::write(&base, ring(24, 1.0, 0.0)).unwrap();
        std::fs::write(&extra, ring(2, 1.1, 0.5)).unwrap();
        let a = CurveArgs {
            input: Some(base),
            output: dir.path().join("e.svg"),
            method: MethodArg::TurkObrien,
            grid: 60,
            epsilon: 0.0,
            offset: 0.1,
            margin: 0.25,
            report: Some(dir.path().join("e.json")),
            dataset: None,
            add: Some(extra),
        };
        run(&a).unwrap();
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("e.json")).unwrap())
                .unwrap();
        let inc = &j["incremental"];
        assert_eq!(inc["added_samples"], 2);
        assert!(inc["max_coefficient_difference_rel"].as_f64().unwrap() <= 1e-9);
        assert!(inc["update_s"].as_f64().unwrap() >= 0.0);
        assert!(inc["fresh_solve_s"].as_f64().unwrap() > 0.0);
        assert_eq!(j["samples"], 26);
        let shen = CurveArgs {
            method: MethodArg::ShenLinear,
            ..a
        };
        assert!(format!("{:#}", run(&shen).unwrap_err()).contains("turk-obrien"));
    }
}
