//! A small fully connected network `f: R² → R` with exact input derivatives up to second order,
//! and the reverse-mode gradient of any linear functional of `(f, ∇f, ∇²f)` with respect to the
//! weights.
//!
//! Forward mode: every neuron carries a 6-channel jet `(v, v_x, v_y, v_xx, v_xy, v_yy)` of its
//! value with respect to the two inputs. A linear layer maps each channel linearly; a smooth
//! activation `h = σ(z)` maps `∇h = σ'(z)∇z` and `∇²h = σ''(z)∇z∇zᵀ + σ'(z)∇²z` (the chain rule
//! to second order). Reverse mode walks the same computation backwards with adjoints for all six
//! channels, which needs `σ'''` for the Hessian channels. Cost per point: `O(6·W)` forward and
//! `O(12·W)` backward for `W` weights (`O(W)` and `O(2W)` in value-only mode).
//!
//! Plain Rust rather than a tensor crate: the network has ~1.2k weights (2–32–32–1), the per-point
//! work is a handful of 32 × 32 mat-vecs that stay in L1 cache, and what is needed (the weight
//! gradient of a loss on *input* Hessians, i.e. third-order mixed derivatives) is a
//! forward-over-reverse composition that general autodiff crates provide only through double
//! backward on a heavy dependency. Here it is ~150 lines that a finite-difference test checks.
//! Reference: Griewank & Walther, *Evaluating Derivatives* (2008), ch. 13 (Taylor propagation).

/// Number of jet channels: value, two first and three second derivatives.
pub const CHANNELS: usize = 6;

/// Hidden-layer activation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Activation {
    /// `tanh z` (default; odd, bounded, smooth).
    Tanh,
    /// `ln(1 + eᶻ)`.
    Softplus,
}

impl Activation {
    /// `(σ, σ', σ'', σ''')` at `z`.
    #[inline]
    pub fn derivatives(self, z: f64) -> [f64; 4] {
        match self {
            Activation::Tanh => {
                let t = z.tanh();
                let d = 1.0 - t * t;
                [t, d, -2.0 * t * d, -2.0 * d * (1.0 - 3.0 * t * t)]
            }
            Activation::Softplus => {
                let s = if z > 0.0 {
                    z + (-z).exp().ln_1p()
                } else {
                    z.exp().ln_1p()
                };
                let g = if z >= 0.0 {
                    1.0 / (1.0 + (-z).exp())
                } else {
                    let e = z.exp();
                    e / (1.0 + e)
                };
                let d2 = g * (1.0 - g);
                [s, g, d2, d2 * (1.0 - 2.0 * g)]
            }
        }
    }
}

/// A multilayer perceptron with `sizes[0] = 2` inputs, one linear output and smooth hidden
/// layers. Weights are flattened layer by layer: `W_l` (`out × in`, row-major) then `b_l`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    /// Layer widths, e.g. `[2, 32, 32, 1]`.
    pub sizes: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// All weights and biases (length [`Mlp::parameter_count`]).
    pub weights: Vec<f64>,
}

/// Per-point scratch: pre- and post-activation jets of every layer (`CHANNELS × width`,
/// channel-major).
#[derive(Debug, Clone)]
pub struct Workspace {
    z: Vec<Vec<f64>>,
    h: Vec<Vec<f64>>,
    zbar: Vec<f64>,
    hbar: Vec<f64>,
}

/// Per-neuron dropout scales of the hidden layers for one point (`1/(1−p)` or `0`); `None` = no
/// dropout.
pub type Mask<'a> = Option<&'a dyn Fn(usize, usize) -> f64>;

impl Mlp {
    /// Weight count of a network with these widths.
    pub fn parameter_count_of(sizes: &[usize]) -> usize {
        sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
    }

    /// Number of weights and biases.
    pub fn parameter_count(&self) -> usize {
        Self::parameter_count_of(&self.sizes)
    }

    /// Offset of layer `l`'s weight block in [`Mlp::weights`].
    fn offset(&self, l: usize) -> usize {
        Self::parameter_count_of(&self.sizes[..=l])
    }

    /// Scratch sized for this network.
    pub fn workspace(&self) -> Workspace {
        let widest = self.sizes.iter().copied().max().unwrap_or(1);
        let layers = self.sizes.len() - 1;
        Workspace {
            z: (0..layers)
                .map(|l| vec![0.0; CHANNELS * self.sizes[l + 1]])
                .collect(),
            h: (0..layers)
                .map(|l| vec![0.0; CHANNELS * self.sizes[l + 1]])
                .collect(),
            zbar: vec![0.0; CHANNELS * widest],
            hbar: vec![0.0; CHANNELS * widest],
        }
    }

    /// Forward pass at `u` (normalised input). With `second`, all six channels; otherwise the
    /// value only. Returns the output jet (`[f, f_x, f_y, f_xx, f_xy, f_yy]`, zeros beyond the
    /// value when `!second`).
    pub fn forward(&self, u: [f64; 2], second: bool, mask: Mask, ws: &mut Workspace) -> [f64; 6] {
        let nc = if second { CHANNELS } else { 1 };
        let input = [u[0], u[1], 1.0, 0.0, 0.0, 1.0];
        let layers = self.sizes.len() - 1;
        for l in 0..layers {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let off = self.offset(l);
            let w = &self.weights[off..off + n_in * n_out];
            let b = &self.weights[off + n_in * n_out..off + n_in * n_out + n_out];
            let (before, rest) = ws.h.split_at_mut(l);
            let z = &mut ws.z[l];
            for j in 0..n_out {
                let row = &w[j * n_in..(j + 1) * n_in];
                for c in 0..nc {
                    z[c * n_out + j] = if l == 0 {
                        // Input jet: channel 0 is u, channels 1–2 the identity, 3–5 zero.
                        match c {
                            0 => row[0] * input[0] + row[1] * input[1],
                            1 => row[0],
                            2 => row[1],
                            _ => 0.0,
                        }
                    } else {
                        let prev = &before[l - 1][c * n_in..(c + 1) * n_in];
                        row.iter().zip(prev).map(|(a, b)| a * b).sum::<f64>()
                    };
                }
                z[j] += b[j];
            }
            if l + 1 == layers {
                break;
            }
            let h = &mut rest[0];
            for j in 0..n_out {
                let [s0, s1, s2, _] = self.activation.derivatives(z[j]);
                let m = mask.map_or(1.0, |f| f(l, j));
                h[j] = m * s0;
                if second {
                    let at = |c: usize| z[c * n_out + j];
                    let (gx, gy) = (at(1), at(2));
                    h[n_out + j] = m * s1 * gx;
                    h[2 * n_out + j] = m * s1 * gy;
                    h[3 * n_out + j] = m * (s2 * gx * gx + s1 * at(3));
                    h[4 * n_out + j] = m * (s2 * gx * gy + s1 * at(4));
                    h[5 * n_out + j] = m * (s2 * gy * gy + s1 * at(5));
                }
            }
        }
        let z = &ws.z[layers - 1];
        let mut out = [0.0; 6];
        for (c, o) in out.iter_mut().enumerate().take(nc) {
            *o = z[c];
        }
        out
    }

    /// Reverse pass after [`Mlp::forward`] at the same `u`, `second` and `mask`: adds
    /// `Σ_c seed[c] · ∂out[c]/∂weights` into `grad` (length [`Mlp::parameter_count`]).
    pub fn backward(
        &self,
        u: [f64; 2],
        second: bool,
        mask: Mask,
        seed: &[f64; 6],
        ws: &mut Workspace,
        grad: &mut [f64],
    ) {
        let nc = if second { CHANNELS } else { 1 };
        let layers = self.sizes.len() - 1;
        ws.zbar[..nc].copy_from_slice(&seed[..nc]);
        let input = [u[0], u[1], 1.0, 0.0, 0.0, 1.0];
        for l in (0..layers).rev() {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let off = self.offset(l);
            let zbar = &ws.zbar[..nc * n_out];
            // Weight and bias gradients: ∂z_j[c]/∂W_jk = h_k[c].
            let (gw, gb) = grad[off..off + n_in * n_out + n_out].split_at_mut(n_in * n_out);
            for j in 0..n_out {
                gb[j] += zbar[j];
                let gr = &mut gw[j * n_in..(j + 1) * n_in];
                for c in 0..nc {
                    let zb = zbar[c * n_out + j];
                    if zb == 0.0 {
                        continue;
                    }
                    if l == 0 {
                        match c {
                            0 => {
                                gr[0] += zb * input[0];
                                gr[1] += zb * input[1];
                            }
                            1 => gr[0] += zb,
                            2 => gr[1] += zb,
                            _ => {}
                        }
                    } else {
                        let prev = &ws.h[l - 1][c * n_in..(c + 1) * n_in];
                        gr.iter_mut().zip(prev).for_each(|(g, h)| *g += zb * h);
                    }
                }
            }
            if l == 0 {
                break;
            }
            // h̄_{l−1} = W_lᵀ z̄_l, channel by channel.
            let w = &self.weights[off..off + n_in * n_out];
            let hbar = &mut ws.hbar[..nc * n_in];
            hbar.iter_mut().for_each(|x| *x = 0.0);
            for j in 0..n_out {
                let row = &w[j * n_in..(j + 1) * n_in];
                for c in 0..nc {
                    let zb = zbar[c * n_out + j];
                    let hb = &mut hbar[c * n_in..(c + 1) * n_in];
                    hb.iter_mut().zip(row).for_each(|(h, a)| *h += zb * a);
                }
            }
            self.activation_backward(l - 1, second, mask, ws);
        }
    }

    /// Adjoint of the activation of hidden layer `l`: `ws.hbar` (post) → `ws.zbar` (pre).
    fn activation_backward(&self, l: usize, second: bool, mask: Mask, ws: &mut Workspace) {
        let n = self.sizes[l + 1];
        let z = &ws.z[l];
        for j in 0..n {
            let m = mask.map_or(1.0, |f| f(l, j));
            let [_, s1, s2, s3] = self.activation.derivatives(z[j]);
            let hb = |c: usize| m * ws.hbar[c * n + j];
            if !second {
                ws.zbar[j] = hb(0) * s1;
                continue;
            }
            let at = |c: usize| z[c * n + j];
            let (gx, gy) = (at(1), at(2));
            let (b0, b1, b2, b3, b4, b5) = (hb(0), hb(1), hb(2), hb(3), hb(4), hb(5));
            let quad = b3 * gx * gx + b4 * gx * gy + b5 * gy * gy;
            let lin = b3 * at(3) + b4 * at(4) + b5 * at(5);
            ws.zbar[j] = b0 * s1 + s2 * (b1 * gx + b2 * gy) + s3 * quad + s2 * lin;
            ws.zbar[n + j] = s1 * b1 + s2 * (2.0 * b3 * gx + b4 * gy);
            ws.zbar[2 * n + j] = s1 * b2 + s2 * (b4 * gx + 2.0 * b5 * gy);
            ws.zbar[3 * n + j] = s1 * b3;
            ws.zbar[4 * n + j] = s1 * b4;
            ws.zbar[5 * n + j] = s1 * b5;
        }
    }

    /// `f(u)` (normalised input).
    pub fn value(&self, u: [f64; 2], ws: &mut Workspace) -> f64 {
        self.forward(u, false, None, ws)[0]
    }
}

/// A tiny deterministic generator (splitmix64), for initialisation, auxiliary points and masks.
#[derive(Debug, Clone)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix(self.0)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// The splitmix64 finaliser (a bijective hash of 64 bits).
pub fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Glorot/Xavier-uniform weights `U(±√(6/(in+out)))`, zero biases, from `seed`.
pub fn xavier(sizes: &[usize], activation: Activation, seed: u64) -> Mlp {
    let mut rng = SplitMix(seed);
    let mut weights = Vec::with_capacity(Mlp::parameter_count_of(sizes));
    for w in sizes.windows(2) {
        let a = (6.0 / (w[0] + w[1]) as f64).sqrt();
        weights.extend((0..w[0] * w[1]).map(|_| a * (2.0 * rng.uniform() - 1.0)));
        weights.extend(std::iter::repeat_n(0.0, w[1]));
    }
    Mlp {
        sizes: sizes.to_vec(),
        activation,
        weights,
    }
}

/// Multiply the first layer's weights by `gain` and draw its biases from `U(±gain/2)`
/// (seeded), so the first-layer transitions are `gain` times sharper and spread over the domain.
pub fn spread_first_layer(net: &mut Mlp, gain: f64, seed: u64) {
    let (n_in, n_out) = (net.sizes[0], net.sizes[1]);
    let mut rng = SplitMix(mix(seed ^ 0x5EED_F1A5));
    let (w, rest) = net.weights.split_at_mut(n_in * n_out);
    w.iter_mut().for_each(|x| *x *= gain);
    rest[..n_out]
        .iter_mut()
        .for_each(|b| *b = gain * (rng.uniform() - 0.5));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net(seed: u64, act: Activation) -> Mlp {
        let mut m = xavier(&[2, 7, 5, 1], act, seed);
        // Non-zero biases so every code path is exercised.
        let mut r = SplitMix(seed ^ 77);
        m.weights
            .iter_mut()
            .for_each(|w| *w += 0.3 * (r.uniform() - 0.5));
        m
    }

    /// Input jets against central differences of the value (first derivatives) and of the
    /// jet's own gradient channels (second derivatives).
    #[test]
    fn exact_input_derivatives_match_finite_differences() {
        for act in [Activation::Tanh, Activation::Softplus] {
            for seed in 0..4 {
                let m = net(seed, act);
                let mut ws = m.workspace();
                let u = [0.3 - 0.1 * seed as f64, -0.2 + 0.05 * seed as f64];
                let j = m.forward(u, true, None, &mut ws);
                let h = 1e-5;
                let at = |du: [f64; 2], ws: &mut Workspace| {
                    m.forward([u[0] + du[0], u[1] + du[1]], true, None, ws)
                };
                let (xp, xm) = (at([h, 0.0], &mut ws), at([-h, 0.0], &mut ws));
                let (yp, ym) = (at([0.0, h], &mut ws), at([0.0, -h], &mut ws));
                let fd = [
                    (xp[0] - xm[0]) / (2.0 * h),
                    (yp[0] - ym[0]) / (2.0 * h),
                    (xp[1] - xm[1]) / (2.0 * h),
                    (yp[1] - ym[1]) / (2.0 * h),
                    (xp[2] - xm[2]) / (2.0 * h),
                    (yp[2] - ym[2]) / (2.0 * h),
                ];
                let exact = [j[1], j[2], j[3], j[4], j[4], j[5]];
                for (a, b) in exact.iter().zip(fd) {
                    assert!((a - b).abs() < 1e-7 * (1.0 + a.abs()), "{act:?} {a} vs {b}");
                }
                assert_eq!(m.forward(u, false, None, &mut ws)[0], j[0]);
            }
        }
    }

    /// Reverse-mode weight gradients of a random linear functional of all six channels (with and
    /// without a dropout mask) against central differences, relative error < 1e-5.
    #[test]
    fn weight_gradient_matches_finite_differences() {
        for act in [Activation::Tanh, Activation::Softplus] {
            for seed in 0..3u64 {
                let mut m = net(seed + 10, act);
                let mut ws = m.workspace();
                let mut r = SplitMix(seed);
                let seedv: [f64; 6] = std::array::from_fn(|_| r.uniform() - 0.5);
                let u = [r.uniform() - 0.5, r.uniform() - 0.5];
                let keep = |l: usize, j: usize| {
                    if (l + j + seed as usize).is_multiple_of(4) {
                        0.0
                    } else {
                        1.25
                    }
                };
                for mask in [None, Some(&keep as &dyn Fn(usize, usize) -> f64)] {
                    for second in [false, true] {
                        let phi = |m: &Mlp, ws: &mut Workspace| {
                            let o = m.forward(u, second, mask, ws);
                            o.iter().zip(&seedv).map(|(a, b)| a * b).sum::<f64>()
                        };
                        let mut g = vec![0.0; m.parameter_count()];
                        m.forward(u, second, mask, &mut ws);
                        m.backward(u, second, mask, &seedv, &mut ws, &mut g);
                        let h = 1e-6;
                        let mut fd = vec![0.0; g.len()];
                        for (i, fdi) in fd.iter_mut().enumerate() {
                            let w0 = m.weights[i];
                            m.weights[i] = w0 + h;
                            let p = phi(&m, &mut ws);
                            m.weights[i] = w0 - h;
                            let q = phi(&m, &mut ws);
                            m.weights[i] = w0;
                            *fdi = (p - q) / (2.0 * h);
                        }
                        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
                        let diff: Vec<f64> = g.iter().zip(&fd).map(|(a, b)| a - b).collect();
                        let rel = norm(&diff) / norm(&fd).max(1e-300);
                        assert!(rel < 1e-5, "{act:?} seed {seed} second {second}: {rel}");
                    }
                }
            }
        }
    }

    #[test]
    fn xavier_is_seeded_and_bounded() {
        let a = xavier(&[2, 32, 32, 1], Activation::Tanh, 5);
        assert_eq!(a, xavier(&[2, 32, 32, 1], Activation::Tanh, 5));
        assert_ne!(a, xavier(&[2, 32, 32, 1], Activation::Tanh, 6));
        assert_eq!(a.parameter_count(), 96 + 1056 + 33);
        let lim = (6.0f64 / 64.0).sqrt();
        assert!(a.weights[96..96 + 1024].iter().all(|w| w.abs() <= lim));
    }
}
