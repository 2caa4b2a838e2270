//! The loss of Jiang & Turk's neural approximator and its full-batch Adam training.
//!
//! `E(θ) = (1/N) Σ_i (f(x_i) − z_i)² + (λ/P) Σ_j f_xx² + 2 f_xy² + f_yy²` (seed 001, eq. 11, as
//! means), with the thin-plate term at `P` auxiliary points uniform over the domain, at the
//! constraint points instead, or absent (plain regression, or regression with inverted dropout on
//! the hidden layers). Per epoch: one forward/backward pass per term point (value-only for pure
//! data terms, second-order jets where the energy is needed), in fixed chunks of
//! [`CHUNK`] points on rayon whose partial gradients are summed in chunk order, so the result
//! does not depend on the thread count. `O(epochs · (N + P) · W)` for `W` weights.
//! Reference: Kingma & Ba, *Adam* (2015); Srivastava et al., *Dropout* (2014).

use rayon::prelude::*;

use super::net::{Mlp, SplitMix, mix};
use super::{DataTerm, MlpParams, Smoothing};
use crate::progress::Progress;
use crate::variational::VariationalError;

/// Points per parallel chunk (fixed, so summation order is fixed).
pub const CHUNK: usize = 16;

/// One point of the loss: a data term `data·(f − target)²` and/or an energy term
/// `energy·(f_xx² + 2f_xy² + f_yy²)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Term {
    /// Position (normalised domain units).
    pub u: [f64; 2],
    /// Target value.
    pub target: f64,
    /// Data-term coefficient (0 for auxiliary points).
    pub data: f64,
    /// Energy-term coefficient (0 without the thin-plate penalty here).
    pub energy: f64,
}

/// The two parts of the loss.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct LossParts {
    /// Weighted data term.
    pub data: f64,
    /// Weighted thin-plate term (includes λ).
    pub energy: f64,
}

impl LossParts {
    /// `data + energy`.
    pub fn total(&self) -> f64 {
        self.data + self.energy
    }
}

/// The loss terms for `constraints` (`(position, target)`, normalised) and auxiliary points
/// under the chosen smoothing.
pub fn build_terms(constraints: &[([f64; 2], f64)], aux: &[[f64; 2]], p: &MlpParams) -> Vec<Term> {
    let n = match p.data_term {
        DataTerm::Sum => 1.0,
        DataTerm::Mean => constraints.len().max(1) as f64,
    };
    let at_constraints = if p.smoothing == Smoothing::ConstraintPoints {
        p.lambda / constraints.len().max(1) as f64
    } else {
        0.0
    };
    let mut t: Vec<Term> = constraints
        .iter()
        .map(|&(u, target)| Term {
            u,
            target,
            data: 1.0 / n,
            energy: at_constraints,
        })
        .collect();
    if p.smoothing == Smoothing::AuxiliaryPoints && p.lambda > 0.0 {
        let e = p.lambda / aux.len().max(1) as f64;
        t.extend(aux.iter().map(|&u| Term {
            u,
            target: 0.0,
            data: 0.0,
            energy: e,
        }));
    }
    t
}

/// `P` points uniform over `[−w/2, w/2] × [−h/2, h/2]` from `seed`.
pub fn auxiliary_points(count: usize, half: [f64; 2], seed: u64) -> Vec<[f64; 2]> {
    let mut r = SplitMix(mix(seed ^ 0xA5A5_5A5A_0F0F_F0F0));
    (0..count)
        .map(|_| {
            let x = (2.0 * r.uniform() - 1.0) * half[0];
            [x, (2.0 * r.uniform() - 1.0) * half[1]]
        })
        .collect()
}

/// Dropout scale of hidden neuron `(l, j)` for term `i` at `epoch`: `0` with probability `rate`,
/// else `1/(1 − rate)`; a pure function of its arguments (deterministic under parallelism).
pub fn dropout_scale(seed: u64, epoch: usize, i: usize, l: usize, j: usize, rate: f64) -> f64 {
    let h =
        mix(mix(mix(seed ^ 0xD80F) ^ epoch as u64)
            ^ ((i as u64) << 20 | (l as u64) << 12 | j as u64));
    let x = (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
    if x < rate { 0.0 } else { 1.0 / (1.0 - rate) }
}

/// Loss and its weight gradient. `dropout = Some((seed, epoch, rate))` applies the training-time
/// masks; `None` evaluates the plain network.
pub fn loss_and_gradient(
    net: &Mlp,
    terms: &[Term],
    dropout: Option<(u64, usize, f64)>,
) -> (LossParts, Vec<f64>) {
    let nw = net.parameter_count();
    let parts: Vec<(LossParts, Vec<f64>)> = terms
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(ci, chunk)| {
            let mut ws = net.workspace();
            let mut g = vec![0.0; nw];
            let mut loss = LossParts::default();
            for (k, t) in chunk.iter().enumerate() {
                let i = ci * CHUNK + k;
                let scale = move |l: usize, j: usize| {
                    dropout.map_or(1.0, |(s, e, r)| dropout_scale(s, e, i, l, j, r))
                };
                let mask: Option<&dyn Fn(usize, usize) -> f64> = if dropout.is_some() {
                    Some(&scale)
                } else {
                    None
                };
                let second = t.energy > 0.0;
                let o = net.forward(t.u, second, mask, &mut ws);
                let r = o[0] - t.target;
                loss.data += t.data * r * r;
                loss.energy += t.energy * (o[3] * o[3] + 2.0 * o[4] * o[4] + o[5] * o[5]);
                let seed = [
                    2.0 * t.data * r,
                    0.0,
                    0.0,
                    2.0 * t.energy * o[3],
                    4.0 * t.energy * o[4],
                    2.0 * t.energy * o[5],
                ];
                net.backward(t.u, second, mask, &seed, &mut ws, &mut g);
            }
            (loss, g)
        })
        .collect();
    let mut total = LossParts::default();
    let mut grad = vec![0.0; nw];
    for (l, g) in parts {
        total.data += l.data;
        total.energy += l.energy;
        grad.iter_mut().zip(&g).for_each(|(a, b)| *a += b);
    }
    (total, grad)
}

/// Mean thin-plate energy `f_xx² + 2f_xy² + f_yy²` of `net` over `pts` (no λ), in a fixed order.
pub fn mean_energy(net: &Mlp, pts: &[[f64; 2]]) -> f64 {
    let mut ws = net.workspace();
    let s: f64 = pts
        .iter()
        .map(|&u| {
            let o = net.forward(u, true, None, &mut ws);
            o[3] * o[3] + 2.0 * o[4] * o[4] + o[5] * o[5]
        })
        .sum();
    s / pts.len().max(1) as f64
}

/// What training did.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TrainingInfo {
    /// Epochs run (≤ the limit; fewer after a plateau stop).
    pub epochs: usize,
    /// True when the plateau test stopped training.
    pub stopped_on_plateau: bool,
    /// Final loss without dropout masks.
    pub loss: LossParts,
    /// Mean thin-plate energy over the auxiliary points (whatever the smoothing), normalised units.
    pub mean_energy_aux: f64,
    /// Largest `|f − z|` over the constraints (normalised targets).
    pub max_abs_residual: f64,
    /// Number of weights.
    pub weights: usize,
    /// Factor applied to the constraint values (1 / their largest magnitude).
    pub target_scale: f64,
    /// Training wall time (seconds).
    pub seconds: f64,
}

/// Adam state.
struct Adam {
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl Adam {
    const B1: f64 = 0.9;
    const B2: f64 = 0.999;
    const EPS: f64 = 1e-8;

    fn step(&mut self, w: &mut [f64], g: &[f64], lr: f64) {
        self.t += 1;
        let c1 = 1.0 - Self::B1.powi(self.t);
        let c2 = 1.0 - Self::B2.powi(self.t);
        for i in 0..w.len() {
            self.m[i] = Self::B1 * self.m[i] + (1.0 - Self::B1) * g[i];
            self.v[i] = Self::B2 * self.v[i] + (1.0 - Self::B2) * g[i] * g[i];
            w[i] -= lr * (self.m[i] / c1) / ((self.v[i] / c2).sqrt() + Self::EPS);
        }
    }
}

/// Train `net` in place on `terms` (full batch, Adam with exponential learning-rate decay from
/// `learning_rate` to `learning_rate · final_lr_fraction`); returns epochs run and whether the
/// plateau test stopped it.
pub fn train(
    net: &mut Mlp,
    terms: &[Term],
    p: &MlpParams,
    progress: &dyn Progress,
) -> Result<(usize, bool), VariationalError> {
    let nw = net.parameter_count();
    let mut adam = Adam {
        m: vec![0.0; nw],
        v: vec![0.0; nw],
        t: 0,
    };
    let report_every = (p.epochs / 200).max(1);
    let mut best = f64::INFINITY;
    let mut best_at_window_start = f64::INFINITY;
    for epoch in 0..p.epochs {
        if progress.cancelled() {
            return Err(VariationalError::Cancelled);
        }
        let dropout = (p.smoothing == Smoothing::Dropout).then_some((p.seed, epoch, p.dropout));
        let (loss, grad) = loss_and_gradient(net, terms, dropout);
        let total = loss.total();
        if !total.is_finite() || grad.iter().any(|g| !g.is_finite()) {
            return Err(VariationalError::TrainingDiverged { epoch });
        }
        best = best.min(total);
        if p.plateau_window > 0 && epoch >= p.min_epochs && epoch % p.plateau_window == 0 {
            if best_at_window_start - best < p.plateau_tolerance * best_at_window_start {
                return Ok((epoch, true));
            }
            best_at_window_start = best;
        }
        let frac = epoch as f64 / (p.epochs.max(2) - 1) as f64;
        let lr = p.learning_rate * p.final_lr_fraction.powf(frac);
        adam.step(&mut net.weights, &grad, lr);
        if epoch % report_every == 0 {
            progress.fraction(epoch as f64 / p.epochs as f64);
        }
    }
    progress.fraction(1.0);
    Ok((p.epochs, false))
}

#[cfg(test)]
mod tests {
    use super::super::net::{Activation, xavier};
    use super::*;

    /// The whole loss (data + thin-plate at auxiliary or constraint points, and with dropout
    /// masks) against central differences on a few random weight sets: relative error < 1e-5.
    #[test]
    fn loss_gradient_matches_finite_differences() {
        let mut r = SplitMix(3);
        let cons: Vec<([f64; 2], f64)> = (0..7)
            .map(|_| ([r.uniform() - 0.5, r.uniform() - 0.5], r.uniform() - 0.5))
            .collect();
        let aux = auxiliary_points(9, [0.6, 0.4], 1);
        for (k, sm) in [
            Smoothing::AuxiliaryPoints,
            Smoothing::ConstraintPoints,
            Smoothing::Off,
            Smoothing::Dropout,
        ]
        .into_iter()
        .enumerate()
        {
            let p = MlpParams {
                smoothing: sm,
                lambda: 0.3,
                ..Default::default()
            };
            let terms = build_terms(&cons, &aux, &p);
            let drop = (sm == Smoothing::Dropout).then_some((9, 4, 0.25));
            let mut net = xavier(&[2, 6, 5, 1], Activation::Tanh, 40 + k as u64);
            let mut r2 = SplitMix(k as u64);
            net.weights
                .iter_mut()
                .for_each(|w| *w += 0.2 * (r2.uniform() - 0.5));
            let (_, g) = loss_and_gradient(&net, &terms, drop);
            let h = 1e-6;
            let mut num = 0.0;
            let mut den = 0.0;
            for (i, gi) in g.iter().enumerate() {
                let w0 = net.weights[i];
                net.weights[i] = w0 + h;
                let a = loss_and_gradient(&net, &terms, drop).0.total();
                net.weights[i] = w0 - h;
                let b = loss_and_gradient(&net, &terms, drop).0.total();
                net.weights[i] = w0;
                let fd = (a - b) / (2.0 * h);
                num += (gi - fd).powi(2);
                den += fd * fd;
            }
            let rel = (num / den).sqrt();
            assert!(rel < 1e-5, "{sm:?}: {rel}");
        }
    }

    #[test]
    fn terms_follow_the_smoothing() {
        let cons = vec![([0.0, 0.0], 0.0), ([0.1, 0.0], -1.0)];
        let aux = auxiliary_points(5, [0.5, 0.5], 0);
        assert!(aux.iter().all(|u| u[0].abs() <= 0.5 && u[1].abs() <= 0.5));
        let t = |sm| {
            build_terms(
                &cons,
                &aux,
                &MlpParams {
                    smoothing: sm,
                    ..Default::default()
                },
            )
        };
        assert_eq!(t(Smoothing::AuxiliaryPoints).len(), 7);
        assert!(
            t(Smoothing::ConstraintPoints)
                .iter()
                .all(|x| x.energy == 0.025)
        );
        assert!(
            t(Smoothing::Off)
                .iter()
                .all(|x| x.energy == 0.0 && x.data == 1.0)
        );
        let kept = (0..10_000)
            .filter(|&i| dropout_scale(1, 2, i, 0, 3, 0.2) > 0.0)
            .count();
        assert!((7800..8200).contains(&kept), "{kept}");
    }
}
