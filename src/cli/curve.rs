//! `rbfsurf curve`: the 2D curves workbench (a thin adapter over
//! [`crate::variational::run_workbench`]).

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::progress::Progress;

use crate::variational::{
    CurveMethod, CurveParams, MlpParams, Offset, WeightPower, curve_io, datasets,
    run_workbench_incremental, workbench::run_workbench_with_progress,
};

/// A progress bar over training epochs (indicatif on stderr; hidden when `quiet` or when stderr
/// is not a terminal, which indicatif detects itself).
struct EpochBar {
    bar: ProgressBar,
}

impl EpochBar {
    const TICKS: u64 = 1000;

    fn new(quiet: bool) -> Self {
        let bar = ProgressBar::with_draw_target(Some(Self::TICKS), ProgressDrawTarget::stderr());
        if quiet {
            bar.set_draw_target(ProgressDrawTarget::hidden());
        }
        if let Ok(style) =
            ProgressStyle::with_template("{elapsed:>4} {msg:<8} [{bar:30}] {percent:>3}% eta {eta}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        EpochBar { bar }
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Progress for EpochBar {
    fn stage(&self, stage: crate::progress::Stage) {
        self.bar.set_message(stage.name());
        self.bar.set_position(0);
    }

    fn fraction(&self, done: f64) {
        self.bar
            .set_position((done.clamp(0.0, 1.0) * Self::TICKS as f64) as u64);
    }

    fn cancelled(&self) -> bool {
        false
    }
}

/// Network options of the MLP methods.
#[derive(Debug, Clone, clap::Args)]
pub struct MlpArgs {
    /// MLP: thin-plate weight λ.
    #[arg(long, default_value_t = 0.05)]
    pub lambda: f64,
    /// MLP: auxiliary points P (uniform over the plot box).
    #[arg(long, default_value_t = 250)]
    pub aux_points: usize,
    /// MLP: epoch limit (training stops earlier on a loss plateau).
    #[arg(long, default_value_t = 3000)]
    pub epochs: usize,
    /// MLP: neurons per hidden layer.
    #[arg(long, default_value_t = 32)]
    pub hidden: usize,
    /// MLP: hidden layers.
    #[arg(long, default_value_t = 2)]
    pub layers: usize,
    /// MLP: initial Adam learning rate (decays exponentially to 5% of it).
    #[arg(long, default_value_t = 1e-2)]
    pub lr: f64,
    /// MLP: first-layer initial weight scale over Xavier (sharper features for > 1).
    #[arg(long, default_value_t = 1.0)]
    pub input_gain: f64,
    /// MLP: scale the constraint values to this largest magnitude (0 keeps them).
    #[arg(long, default_value_t = 1.0)]
    pub target_peak: f64,
    /// MLP: plateau test window in epochs (0 = always run every epoch).
    #[arg(long, default_value_t = 250)]
    pub plateau_window: usize,
    /// MLP: dropout rate of mlp-dropout.
    #[arg(long, default_value_t = 0.1)]
    pub dropout: f64,
    /// MLP: seed of the weights, auxiliary points and dropout masks.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Do not draw the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

impl MlpArgs {
    fn params(&self) -> MlpParams {
        MlpParams {
            lambda: self.lambda,
            aux_points: self.aux_points,
            epochs: self.epochs,
            hidden: self.hidden,
            layers: self.layers,
            learning_rate: self.lr,
            dropout: self.dropout,
            input_gain: self.input_gain,
            target_peak: self.target_peak,
            plateau_window: self.plateau_window,
            seed: self.seed,
            ..Default::default()
        }
    }
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
    #[arg(long, value_enum, default_value_t = CurveMethod::TurkObrien)]
    pub method: CurveMethod,
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
    /// Use a built-in data set instead of a file (shen27, koch0..koch6, koch1-interior, koch2-interior, square, unit-square-centre, five-point, circle8).
    #[arg(long)]
    pub dataset: Option<String>,
    /// MLP options.
    #[command(flatten)]
    pub mlp: MlpArgs,
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
    let params = CurveParams {
        method: a.method,
        grid: a.grid,
        epsilon: a.epsilon,
        weight: WeightPower::Auto,
        offset: Offset::SpacingFraction(a.offset),
        margin: a.margin,
        mlp: a.mlp.params(),
        ..Default::default()
    };
    let out = match &a.add {
        None => {
            let bar = EpochBar::new(a.mlp.quiet || params.method.mlp_smoothing().is_none());
            let out = run_workbench_with_progress(&samples, &params, &bar);
            bar.finish();
            out.map_err(|e| match &a.input {
                Some(p) => with_lines(e, p, &lines),
                None => e.into(),
            })?
        }
        Some(path) => {
            let (extra, _) = read_samples(path)?;
            run_workbench_incremental(&samples, &extra, &params)
                .with_context(|| format!("adding the constraints of {}", path.display()))?
        }
    };
    crate::io::write_atomic(&a.output, out.svg.as_bytes())?;
    if let Some(r) = &a.report {
        crate::io::write_atomic(r, serde_json::to_string_pretty(&out.report)?.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mlp_defaults() -> MlpArgs {
        MlpArgs {
            lambda: 0.05,
            aux_points: 250,
            epochs: 3000,
            hidden: 32,
            layers: 2,
            lr: 1e-2,
            dropout: 0.1,
            input_gain: 1.0,
            target_peak: 1.0,
            plateau_window: 250,
            seed: 1,
            quiet: true,
        }
    }

    #[test]
    fn dataset_to_svg_and_report() {
        let dir = tempfile::tempdir().unwrap();
        let a = CurveArgs {
            input: None,
            output: dir.path().join("k.svg"),
            method: CurveMethod::ShenLinearNormals,
            grid: 60,
            epsilon: 0.0,
            offset: 0.1,
            margin: 0.25,
            report: Some(dir.path().join("k.json")),
            dataset: Some("koch1".into()),
            mlp: mlp_defaults(),
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
        assert_eq!(
            crate::cli::run([
                "rbfsurf",
                "curve",
                "--dataset",
                "five-point",
                "--method",
                "mlp-noreg",
                "--epochs",
                "200",
                "--hidden",
                "8",
                "--quiet",
                "-o",
                dir.path().join("m.svg").to_str().unwrap(),
                "--report",
                dir.path().join("m.json").to_str().unwrap(),
            ]),
            0
        );
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("m.json")).unwrap())
                .unwrap();
        assert_eq!(m["method"], "mlp-noreg");
        assert_eq!(m["mlp"]["smoothing"], "off");
        assert_eq!(m["training"]["weights"], 2 * 8 + 8 + 8 * 8 + 8 + 9);
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
            method: CurveMethod::TurkObrien,
            grid: 40,
            epsilon: 0.0,
            offset: 0.1,
            margin: 0.25,
            report: None,
            dataset: None,
            add: None,
            mlp: mlp_defaults(),
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
            method: CurveMethod::TurkObrien,
            grid: 60,
            epsilon: 0.0,
            offset: 0.1,
            margin: 0.25,
            report: Some(dir.path().join("e.json")),
            dataset: None,
            add: Some(extra),
            mlp: mlp_defaults(),
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
            method: CurveMethod::ShenLinear,
            ..a
        };
        assert!(format!("{:#}", run(&shen).unwrap_err()).contains("turk-obrien"));
    }
}
