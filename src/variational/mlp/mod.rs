//! Jiang & Turk's neural implicit approximator (seed 001, §3.2 and §4.2): a small MLP
//! `f(x, y)` fitted to the 2D constraints (on-curve 0, interior < 0, exterior > 0 — the crate's
//! sign convention; the seed's `+1` interior is `−1` here) with the loss
//! `mean data residual² + λ · mean thin-plate energy f_xx² + 2f_xy² + f_yy²` at `P` auxiliary
//! points uniform over the domain, and the seed's three baselines ([`Smoothing`]).
//!
//! Coordinates: the domain rectangle (the workbench's sampling box) is mapped to a centred
//! rectangle of area 1, as the seed assumes ("Ω … area 1 without loss of generality"), so λ has
//! the seed's meaning. Samples with normals also get pseudo-normal points on both sides at
//! `±δ` with values `±δ` (domain units), so data sets given as on-curve points with normals
//! (Koch, Shen) have interior and exterior constraints like the seed's figures.
//!
//! Cost: `O(epochs · (N + P) · W)` training for `W` ≈ 1.2k weights (see [`train`]), then
//! `O(W)` per field evaluation. Second derivatives are exact (forward-mode jets, [`net`]).

pub(crate) mod net;
pub(crate) mod train;

use std::time::Instant;

use super::constraints::{
    Offset, Origin, PseudoNormalParams, Sample, Sides, ValueConstraint, VariationalError,
    expand_pseudo_normals, extent, validate_samples,
};
use super::{Frame, ImplicitField};
use crate::progress::Progress;
pub use net::{Activation, Mlp};
pub use train::{LossParts, TrainingInfo};

/// Where the smoothness comes from (the seed's method and its three baselines, Fig. 3–4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Smoothing {
    /// Thin-plate energy at `P` auxiliary points uniform over the domain (the seed's method).
    AuxiliaryPoints,
    /// Thin-plate energy at the constraint points only (baseline b).
    ConstraintPoints,
    /// No regulariser, λ = 0 (baseline a).
    Off,
    /// No thin-plate term; inverted dropout on the hidden layers during training (baseline c).
    Dropout,
}

/// How the data residuals are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DataTerm {
    /// `Σ_i (f(x_i) − z_i)²`, as in the seed's eq. 11 (default; λ = 0.05 is calibrated for it).
    Sum,
    /// `(1/N) Σ_i (f(x_i) − z_i)²`.
    Mean,
}

/// Network and training parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MlpParams {
    /// Neurons per hidden layer (default 32; 4..=256).
    pub hidden: usize,
    /// Hidden layers (default 2; 1..=4).
    pub layers: usize,
    /// Scale of the first layer's initial weights over Xavier's (default 1 = Xavier); with
    /// `g > 1` the first-layer biases are also spread `U(±g/2)` so the units' transitions cover
    /// the domain. Larger values let the network resolve features small against the domain.
    pub input_gain: f64,
    /// Hidden activation (default tanh).
    pub activation: Activation,
    /// Regulariser (default thin-plate at auxiliary points).
    pub smoothing: Smoothing,
    /// Constraint values are scaled so the largest magnitude is this (default 1, the seed's
    /// ±1; 0 keeps the values: pseudo-normal points then ask for `±δ`, a unit-slope field).
    pub target_peak: f64,
    /// Data-term normalisation (default the seed's sum).
    pub data_term: DataTerm,
    /// Thin-plate weight λ (default 0.05, the seed's; ≥ 0).
    pub lambda: f64,
    /// Auxiliary points `P` (default 250, the seed's; ≥ 1 for [`Smoothing::AuxiliaryPoints`]).
    pub aux_points: usize,
    /// Epoch limit (default 3000).
    pub epochs: usize,
    /// Initial Adam step (default 1e-2).
    pub learning_rate: f64,
    /// Learning rate at the last epoch as a fraction of the first (exponential decay; default 0.05).
    pub final_lr_fraction: f64,
    /// Dropout rate for [`Smoothing::Dropout`] (default 0.1; in `[0, 1)`).
    pub dropout: f64,
    /// Seed of the initial weights, auxiliary points and dropout masks (default 1).
    pub seed: u64,
    /// Plateau test every this many epochs (default 250; 0 = never stop early).
    pub plateau_window: usize,
    /// No plateau stop before this many epochs (default 1500: fits that start near the trivial
    /// `f ≈ 0` saddle can sit on a plateau for ~1000 epochs before they escape).
    pub min_epochs: usize,
    /// Stop when the best loss improved by less than this fraction over a window (default 1e-3).
    pub plateau_tolerance: f64,
}

impl Default for MlpParams {
    fn default() -> Self {
        MlpParams {
            hidden: 32,
            layers: 2,
            input_gain: 1.0,
            activation: Activation::Tanh,
            smoothing: Smoothing::AuxiliaryPoints,
            data_term: DataTerm::Sum,
            target_peak: 1.0,
            lambda: 0.05,
            aux_points: 250,
            epochs: 3000,
            learning_rate: 1e-2,
            final_lr_fraction: 0.05,
            dropout: 0.1,
            seed: 1,
            plateau_window: 250,
            min_epochs: 1500,
            plateau_tolerance: 1e-3,
        }
    }
}

impl MlpParams {
    /// Check ranges.
    pub fn validate(&self) -> Result<(), VariationalError> {
        let bad = |name, value: f64, reason| {
            Err(VariationalError::InvalidParameter {
                name,
                value,
                reason,
            })
        };
        if !(4..=256).contains(&self.hidden) {
            return bad("hidden", self.hidden as f64, "must be 4..=256");
        }
        if !(1..=4).contains(&self.layers) {
            return bad("layers", self.layers as f64, "must be 1..=4");
        }
        if !(self.input_gain > 0.0 && self.input_gain <= 1e3) {
            return bad("input_gain", self.input_gain, "must be in (0, 1000]");
        }
        if !(self.target_peak >= 0.0 && self.target_peak.is_finite()) {
            return bad("target_peak", self.target_peak, "must be finite and >= 0");
        }
        if !(self.lambda >= 0.0 && self.lambda.is_finite()) {
            return bad("lambda", self.lambda, "must be finite and >= 0");
        }
        if self.smoothing == Smoothing::AuxiliaryPoints && self.aux_points == 0 {
            return bad(
                "aux_points",
                0.0,
                "must be >= 1 with auxiliary-point smoothing",
            );
        }
        if !(1..=1_000_000).contains(&self.epochs) {
            return bad("epochs", self.epochs as f64, "must be 1..=1000000");
        }
        if !(self.learning_rate > 0.0 && self.learning_rate < 1.0) {
            return bad("learning_rate", self.learning_rate, "must be in (0, 1)");
        }
        if !(self.final_lr_fraction > 0.0 && self.final_lr_fraction <= 1.0) {
            return bad(
                "final_lr_fraction",
                self.final_lr_fraction,
                "must be in (0, 1]",
            );
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return bad("dropout", self.dropout, "must be in [0, 1)");
        }
        if self.plateau_tolerance.is_nan() || self.plateau_tolerance < 0.0 {
            return bad("plateau_tolerance", self.plateau_tolerance, "must be >= 0");
        }
        Ok(())
    }

    /// Layer widths `[2, hidden × layers, 1]`.
    pub fn sizes(&self) -> Vec<usize> {
        let mut s = vec![2];
        s.extend(std::iter::repeat_n(self.hidden, self.layers));
        s.push(1);
        s
    }
}

/// A trained network as a field in input units.
#[derive(Debug, Clone)]
pub struct MlpFit {
    /// The network (inputs in domain units).
    pub net: Mlp,
    /// Input units → domain units (area-1 domain).
    pub frame: Frame<2>,
    /// Every constraint used (input units; values in target units).
    pub constraints: Vec<ValueConstraint<2>>,
    /// The auxiliary points (input units).
    pub aux: Vec<[f64; 2]>,
    /// Training summary.
    pub info: TrainingInfo,
}

impl ImplicitField<2> for MlpFit {
    fn value(&self, x: &[f64; 2]) -> f64 {
        let mut ws = self.net.workspace();
        self.net.value(self.frame.forward(x), &mut ws)
    }

    fn gradient(&self, x: &[f64; 2]) -> [f64; 2] {
        let mut ws = self.net.workspace();
        let o = self.net.forward(self.frame.forward(x), true, None, &mut ws);
        [o[1] / self.frame.scale, o[2] / self.frame.scale]
    }
}

/// The constraints in domain units: samples plus pseudo-normal points on both sides, values
/// scaled to `p.target_peak`; returns them and the scale applied.
fn domain_constraints(
    samples: &[Sample<2>],
    frame: &Frame<2>,
    offset: Offset,
    p: &MlpParams,
) -> Result<(Vec<ValueConstraint<2>>, f64), VariationalError> {
    let norm: Vec<Sample<2>> = samples
        .iter()
        .map(|s| Sample {
            p: frame.forward(&s.p),
            ..*s
        })
        .collect();
    let unit = extent(norm.iter().map(|s| s.p)).max(f64::MIN_POSITIVE);
    let pseudo = PseudoNormalParams {
        offset,
        sides: Sides::Both,
    };
    let mut cons = expand_pseudo_normals(&norm, &pseudo, unit)?;
    // Targets scaled to max |z| = 1 (the seed's ±1), so Adam's steps fit the output scale.
    let zmax = cons.iter().map(|c| c.value.abs()).fold(0.0, f64::max);
    let target_scale = if zmax > 0.0 && p.target_peak > 0.0 {
        p.target_peak / zmax
    } else {
        1.0
    };
    cons.iter_mut().for_each(|c| c.value *= target_scale);
    Ok((cons, target_scale))
}

/// Fit the network to `samples` over the `domain` rectangle (`(min, max)`, input units).
///
/// Errors: invalid parameters or samples, a degenerate domain, `Cancelled` when `progress` asks,
/// `TrainingDiverged` on a non-finite loss.
pub fn fit_mlp(
    samples: &[Sample<2>],
    domain: ([f64; 2], [f64; 2]),
    offset: Offset,
    p: &MlpParams,
    progress: &dyn Progress,
) -> Result<MlpFit, VariationalError> {
    p.validate()?;
    validate_samples(samples)?;
    let (lo, hi) = domain;
    let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
    if !(w > 0.0 && h > 0.0 && (w * h).is_finite()) {
        return Err(VariationalError::InvalidParameter {
            name: "bounds",
            value: w.min(h),
            reason: "need a non-empty finite rectangle",
        });
    }
    let frame = Frame {
        centre: [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])],
        scale: (w * h).sqrt(),
    };
    let (cons, target_scale) = domain_constraints(samples, &frame, offset, p)?;
    let pairs: Vec<([f64; 2], f64)> = cons.iter().map(|c| (c.p, c.value)).collect();
    let half = [0.5 * w / frame.scale, 0.5 * h / frame.scale];
    let aux = train::auxiliary_points(p.aux_points, half, p.seed);
    let terms = train::build_terms(&pairs, &aux, p);
    let mut net = net::xavier(&p.sizes(), p.activation, p.seed);
    if p.input_gain != 1.0 {
        net::spread_first_layer(&mut net, p.input_gain, p.seed);
    }
    progress.stage(crate::progress::Stage::Train);
    let t0 = Instant::now();
    let (epochs, stopped_on_plateau) = train::train(&mut net, &terms, p, progress)?;
    let seconds = t0.elapsed().as_secs_f64();
    let plain = MlpParams {
        smoothing: Smoothing::Off,
        ..*p
    };
    let data_terms = train::build_terms(&pairs, &aux, &plain);
    let (mut loss, _) = train::loss_and_gradient(&net, &data_terms, None);
    loss.energy = train::loss_and_gradient(&net, &terms, None).0.energy;
    let mut ws = net.workspace();
    let max_abs_residual = pairs
        .iter()
        .map(|&(u, z)| (net.value(u, &mut ws) - z).abs())
        .fold(0.0, f64::max);
    let info = TrainingInfo {
        epochs,
        stopped_on_plateau,
        loss,
        mean_energy_aux: train::mean_energy(&net, &aux),
        max_abs_residual,
        weights: net.parameter_count(),
        target_scale,
        seconds,
    };
    let constraints = cons
        .iter()
        .map(|c| ValueConstraint {
            p: frame.inverse(&c.p),
            ..*c
        })
        .collect();
    Ok(MlpFit {
        net,
        frame,
        constraints,
        aux: aux.iter().map(|u| frame.inverse(u)).collect(),
        info,
    })
}

/// The generated pseudo-normal constraints of a fit (for plots).
pub fn pseudo_points(fit: &MlpFit) -> Vec<ValueConstraint<2>> {
    fit.constraints
        .iter()
        .filter(|c| matches!(c.origin, Origin::PseudoNormal { .. }))
        .copied()
        .collect()
}

#[cfg(test)]
mod tests;
