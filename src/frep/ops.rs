//! Evaluation of a composite solid (F-rep, `F ≥ 0` inside, input units) and the value bounds that
//! let the sparse polygonizer skip cells.
//!
//! - Primitives are exact signed distances (`F = −distance`, 1-Lipschitz), so over a cell of half
//!   diagonal `h` around its centre `c`, `F ∈ [F(c) − h, F(c) + h]`.
//! - A field operand is bounded by its own skip test ([`ScalarField::may_contain_zero`]): where it
//!   says the surface does not pass, the sign at the centre holds on the whole cell and the bound is
//!   `(0⁺, ∞)` or `(−∞, 0⁻)`; elsewhere `(−∞, ∞)`.
//! - R-functions (Rvachev; Pasko et al. 1995) `u(a, b) = (a + b ± √(a² + b² − 2αab)) / (1 + α)`,
//!   `α ∈ (−1, 1]` (0 by default; 1 gives max/min), are non-decreasing in both arguments, so the
//!   bound of a union or intersection is the function of the bounds' ends, with the limits
//!   `u∪(−∞, b) = b`, `u∪(+∞, b) = +∞`, `u∩(+∞, b) = b`, `u∩(−∞, b) = −∞`. Difference is
//!   `a ∩ ¬b`.
//! - `blend(a, b, a₀)` is Pasko's blending union `u∪(a, b) + a₀ / (1 + (a/a₀)² + (b/a₀)²)`; the
//!   displacement lies in `[a₀ / (1 + A² + B²), a₀ / (1 + m_a² + m_b²)]` with `m`, `M` the smallest and
//!   largest `|value|/a₀` over the bounds.
//! - `offset(a, d) = F_a / |∇F_a| + d` (gradient by central differences): a first-order signed
//!   distance near the surface, exact for the primitives. Its bound is the sign of `a` on the cell
//!   grown by `2|d|` when `a` has no zero there (it assumes `F_a / |∇F_a|` is within a factor 2 of the
//!   distance up to `2|d|` from the surface), else unbounded.
//! - Affine maps evaluate the operand at the inverse-mapped point (`scale` also multiplies the value
//!   by `s`, so it stays a distance); their bound is the operand's over the mapped cell's box.

use super::FieldModel;
use crate::geometry::{Aabb, Point3, dot, norm, sub};
use crate::polygonize::ScalarField;
use std::sync::Arc;

/// A composite solid: F-rep, `F ≥ 0` inside, input units.
pub enum Solid {
    /// A saved (or just fitted) field.
    Field(Arc<FieldModel>),
    /// Ball: centre, radius.
    Sphere(Point3, f64),
    /// Axis-aligned box: lower and upper corners.
    Box(Aabb),
    /// Capped cylinder between two axis end points, radius.
    Cylinder(Point3, Point3, f64),
    /// Torus around the z axis through the centre: centre, major radius, minor radius.
    Torus(Point3, f64, f64),
    /// R-union with parameter `α`.
    Union(Box<Solid>, Box<Solid>, f64),
    /// R-intersection with parameter `α`.
    Intersection(Box<Solid>, Box<Solid>, f64),
    /// R-difference (`a ∩ ¬b`) with parameter `α`.
    Difference(Box<Solid>, Box<Solid>, f64),
    /// Blending union with displacement amount `a₀` (input units).
    Blend(Box<Solid>, Box<Solid>, f64),
    /// Offset by `d` (input units, > 0 grows), gradient step `h`.
    Offset(Box<Solid>, f64, f64),
    /// `F(x) = gain · F_child(M x + t)`.
    Affine(Box<Solid>, Affine),
    /// A solid shared with other expressions.
    Shared(Arc<Solid>),
    /// `(1 − t) F_a + t F_b` (metamorphosis), meshed in the given box.
    Morph(Arc<Solid>, Arc<Solid>, f64, Aabb),
}

/// `x ↦ M x + t` (the inverse of the user's map) and the value gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine {
    /// Linear part, row-major.
    pub m: [[f64; 3]; 3],
    /// Translation.
    pub t: Point3,
    /// Value multiplier (the scale factor for `scale`, 1 otherwise).
    pub gain: f64,
}

impl Affine {
    /// Apply to a point.
    pub fn apply(&self, x: &Point3) -> Point3 {
        [0, 1, 2].map(|i| dot(self.m[i], *x) + self.t[i])
    }

    /// Box of the mapped corners of `b`.
    pub fn apply_box(&self, b: &Aabb) -> Aabb {
        Aabb::from_points(&b.corners().map(|c| self.apply(&c)))
    }

    /// The map and its inverse for `translate`, `scale` and `rotate` (forward maps of the user).
    pub fn inverse_of(m: [[f64; 3]; 3], t: Point3) -> Option<Affine> {
        let inv = invert3(m)?;
        let it = [0, 1, 2].map(|i| -dot(inv[i], t));
        Some(Affine {
            m: inv,
            t: it,
            gain: 1.0,
        })
    }
}

fn invert3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |r: usize, s: usize| {
        let (r1, r2, s1, s2) = ((r + 1) % 3, (r + 2) % 3, (s + 1) % 3, (s + 2) % 3);
        m[r1][s1] * m[r2][s2] - m[r1][s2] * m[r2][s1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if !(det.abs() > 1e-300 && det.is_finite()) {
        return None;
    }
    Some([0, 1, 2].map(|i| [0, 1, 2].map(|j| c(j, i) / det)))
}

/// An interval of values `[lo, hi]` over a cell (ends may be infinite). A strictly positive or
/// strictly negative interval means the surface does not pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
}

impl Bound {
    const ANY: Bound = Bound {
        lo: f64::NEG_INFINITY,
        hi: f64::INFINITY,
    };
    const INSIDE: Bound = Bound {
        lo: f64::MIN_POSITIVE,
        hi: f64::INFINITY,
    };
    const OUTSIDE: Bound = Bound {
        lo: f64::NEG_INFINITY,
        hi: -f64::MIN_POSITIVE,
    };

    /// Whether the surface `F = 0` may pass.
    pub fn may_contain_zero(&self) -> bool {
        !(self.lo > 0.0 || self.hi < 0.0)
    }

    fn around(v: f64, h: f64) -> Bound {
        Bound {
            lo: v - h,
            hi: v + h,
        }
    }
}

/// R-union of two values with parameter `α` (limits at ±∞ as in the module doc).
pub fn r_union(a: f64, b: f64, alpha: f64) -> f64 {
    if a == f64::INFINITY || b == f64::INFINITY {
        return f64::INFINITY;
    }
    if a == f64::NEG_INFINITY {
        return b;
    }
    if b == f64::NEG_INFINITY {
        return a;
    }
    let r = (a * a + b * b - 2.0 * alpha * a * b).max(0.0).sqrt();
    let u = (a + b + r) / (1.0 + alpha);
    // The sign law of the R-union (positive iff an operand is), which rounding in `a + b + r` can
    // break when one operand is far smaller than the other.
    if a > 0.0 || b > 0.0 {
        u.max(f64::MIN_POSITIVE)
    } else if a < 0.0 && b < 0.0 {
        u.min(-f64::MIN_POSITIVE)
    } else {
        u
    }
}

/// `(u∪(a, b), ∂u/∂a, ∂u/∂b)` for finite `a`, `b`.
fn r_union_partials(a: f64, b: f64, alpha: f64) -> (f64, f64, f64) {
    let r = (a * a + b * b - 2.0 * alpha * a * b).max(0.0).sqrt();
    let k = 1.0 / (1.0 + alpha);
    if r == 0.0 {
        return ((a + b) * k, k, k);
    }
    (
        (a + b + r) * k,
        (1.0 + (a - alpha * b) / r) * k,
        (1.0 + (b - alpha * a) / r) * k,
    )
}

/// `p·g + q·h`.
fn combine(p: f64, g: Point3, q: f64, h: Point3) -> Point3 {
    [0, 1, 2].map(|k| p * g[k] + q * h[k])
}

/// R-intersection: `−u∪(−a, −b)`.
pub fn r_intersection(a: f64, b: f64, alpha: f64) -> f64 {
    -r_union(-a, -b, alpha)
}

/// Pasko's displacement `a₀ / (1 + (a/a₀)² + (b/a₀)²)`.
fn displacement(a: f64, b: f64, a0: f64) -> f64 {
    let (u, v) = (a / a0, b / a0);
    let d = a0 / (1.0 + u * u + v * v);
    if d.is_finite() { d } else { 0.0 }
}

/// Smallest and largest `|v|` over a bound.
fn abs_range(b: Bound) -> (f64, f64) {
    let min = if b.lo <= 0.0 && b.hi >= 0.0 {
        0.0
    } else {
        b.lo.abs().min(b.hi.abs())
    };
    (min, b.lo.abs().max(b.hi.abs()))
}

fn sphere_sd(x: &Point3, c: &Point3, r: f64) -> f64 {
    norm(sub(*x, *c)) - r
}

fn box_sd(x: &Point3, b: &Aabb) -> f64 {
    let c = b.center();
    let e = b.extent();
    let q: Point3 = [0, 1, 2].map(|k| (x[k] - c[k]).abs() - 0.5 * e[k]);
    let outside = norm(q.map(|v| v.max(0.0)));
    outside + q[0].max(q[1]).max(q[2]).min(0.0)
}

fn cylinder_sd(x: &Point3, a: &Point3, b: &Point3, r: f64) -> f64 {
    let ba = sub(*b, *a);
    let pa = sub(*x, *a);
    let l = norm(ba);
    let axial = dot(pa, ba) / l;
    let radial = (dot(pa, pa) - axial * axial).max(0.0).sqrt();
    let dr = radial - r;
    let dz = (axial - 0.5 * l).abs() - 0.5 * l;
    let out = (dr.max(0.0).powi(2) + dz.max(0.0).powi(2)).sqrt();
    out + dr.max(dz).min(0.0)
}

fn torus_sd(x: &Point3, c: &Point3, major: f64, minor: f64) -> f64 {
    let d = sub(*x, *c);
    let q = ((d[0] * d[0] + d[1] * d[1]).sqrt() - major, d[2]);
    (q.0 * q.0 + q.1 * q.1).sqrt() - minor
}

impl Solid {
    /// `F(x)`, ≥ 0 inside.
    pub fn value(&self, x: &Point3) -> f64 {
        match self {
            Solid::Field(m) => m.value(x),
            Solid::Sphere(c, r) => -sphere_sd(x, c, *r),
            Solid::Box(b) => -box_sd(x, b),
            Solid::Cylinder(a, b, r) => -cylinder_sd(x, a, b, *r),
            Solid::Torus(c, big, small) => -torus_sd(x, c, *big, *small),
            Solid::Union(a, b, al) => r_union(a.value(x), b.value(x), *al),
            Solid::Intersection(a, b, al) => r_intersection(a.value(x), b.value(x), *al),
            Solid::Difference(a, b, al) => r_intersection(a.value(x), -b.value(x), *al),
            Solid::Blend(a, b, a0) => {
                let (u, v) = (a.value(x), b.value(x));
                r_union(u, v, 0.0) + displacement(u, v, *a0)
            }
            Solid::Offset(a, d, h) => {
                let mut pts = vec![*x];
                push_stencil(x, *h, &mut pts);
                let mut vals = vec![0.0; 7];
                a.values(&Aabb::from_points(&pts), &pts, &mut vals);
                normalised(&vals, *h) + d
            }
            Solid::Affine(a, map) => map.gain * a.value(&map.apply(x)),
            Solid::Shared(a) => a.value(x),
            Solid::Morph(a, b, t, _) => (1.0 - t) * a.value(x) + t * b.value(x),
        }
    }

    /// `F` at each of `points` (all inside `region`), written to `out`. Field operands gather their
    /// spline centres once for the region.
    pub fn values(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        self.values_with(region, points, out, None);
    }

    /// [`Self::values`], or with `sign_only` (a cache) values that have the same sign and zero set as `F`
    /// but cost less: an R-function operand whose sign is fixed on `region` (its bound) is not
    /// evaluated but replaced by its value at the region's centre. The zero set of an R-function
    /// depends only on where its operands vanish and their signs, so the result's signs and zero
    /// set are unchanged; only operations that use magnitudes (blend, offset, morph) ask their
    /// operands for exact values. What the polygonizer's grid corners use.
    pub fn values_with(
        &self,
        region: &Aabb,
        points: &[Point3],
        out: &mut [f64],
        sign_only: Option<&SignCache>,
    ) {
        match self {
            Solid::Field(m) => {
                let n = &m.normalization;
                let pts: Vec<Point3> = points.iter().map(|p| n.forward(p)).collect();
                let r = Aabb {
                    min: n.forward(&region.min),
                    max: n.forward(&region.max),
                };
                m.rbf.values_in(&r, &pts, out);
                for o in out.iter_mut() {
                    *o = -*o / n.scale;
                }
            }
            Solid::Union(a, b, al)
            | Solid::Intersection(a, b, al)
            | Solid::Difference(a, b, al) => {
                let mut second = vec![0.0; points.len()];
                operand(a, region, points, out, sign_only);
                operand(b, region, points, &mut second, sign_only);
                for (o, v) in out.iter_mut().zip(second) {
                    *o = match self {
                        Solid::Union(..) => r_union(*o, v, *al),
                        Solid::Intersection(..) => r_intersection(*o, v, *al),
                        _ => r_intersection(*o, -v, *al),
                    };
                }
            }
            Solid::Blend(a, b, a0) => {
                let mut second = vec![0.0; points.len()];
                a.values(region, points, out);
                b.values(region, points, &mut second);
                for (o, v) in out.iter_mut().zip(second) {
                    *o = r_union(*o, v, 0.0) + displacement(*o, v, *a0);
                }
            }
            Solid::Offset(a, d, h) => {
                let mut pts = Vec::with_capacity(points.len() * 7);
                for p in points {
                    pts.push(*p);
                    push_stencil(p, *h, &mut pts);
                }
                let mut vals = vec![0.0; pts.len()];
                a.values(&region.inflated(*h), &pts, &mut vals);
                for (o, v) in out.iter_mut().zip(vals.chunks_exact(7)) {
                    *o = normalised(v, *h) + d;
                }
            }
            Solid::Affine(a, map) => {
                let pts: Vec<Point3> = points.iter().map(|p| map.apply(p)).collect();
                a.values_with(&map.apply_box(region), &pts, out, sign_only);
                out.iter_mut().for_each(|o| *o *= map.gain);
            }
            Solid::Shared(a) => a.values_with(region, points, out, sign_only),
            Solid::Morph(a, b, t, _) => {
                let mut second = vec![0.0; points.len()];
                a.values(region, points, out);
                b.values(region, points, &mut second);
                for (o, v) in out.iter_mut().zip(second) {
                    *o = (1.0 - t) * *o + t * v;
                }
            }
            _ => {
                for (p, o) in points.iter().zip(out.iter_mut()) {
                    *o = self.value(p);
                }
            }
        }
    }

    /// `(F(x), ∇F(x))`: analytic through the operations and the fields (chain rule), central
    /// differences on primitives and offsets.
    pub fn value_gradient(&self, x: &Point3) -> (f64, Point3) {
        match self {
            Solid::Field(m) => {
                let p = m.normalization.forward(x);
                let g = m.rbf.gradient(&p);
                (m.value(x), g.map(|c| -c))
            }
            Solid::Union(a, b, al)
            | Solid::Intersection(a, b, al)
            | Solid::Difference(a, b, al) => {
                let ((u, gu), (mut v, mut gv)) = (a.value_gradient(x), b.value_gradient(x));
                if matches!(self, Solid::Difference(..)) {
                    v = -v;
                    gv = gv.map(|c| -c);
                }
                let union = matches!(self, Solid::Union(..));
                let s = if union { 1.0 } else { -1.0 };
                let (f, da, db) = r_union_partials(s * u, s * v, *al);
                (s * f, combine(da, gu, db, gv))
            }
            Solid::Blend(a, b, a0) => {
                let ((u, gu), (v, gv)) = (a.value_gradient(x), b.value_gradient(x));
                let (f, da, db) = r_union_partials(u, v, 0.0);
                let (p, q) = (u / a0, v / a0);
                let den = 1.0 + p * p + q * q;
                let (dd_a, dd_b) = (-2.0 * p / (den * den), -2.0 * q / (den * den));
                let d = displacement(u, v, *a0);
                (f + d, combine(da + dd_a, gu, db + dd_b, gv))
            }
            Solid::Affine(a, map) => {
                let (v, g) = a.value_gradient(&map.apply(x));
                let mt = [0, 1, 2].map(|j| (0..3).map(|i| map.m[i][j] * g[i]).sum::<f64>());
                (map.gain * v, mt.map(|c| map.gain * c))
            }
            Solid::Shared(a) => a.value_gradient(x),
            Solid::Morph(a, b, t, _) => {
                let ((u, gu), (v, gv)) = (a.value_gradient(x), b.value_gradient(x));
                ((1.0 - t) * u + t * v, combine(1.0 - t, gu, *t, gv))
            }
            _ => {
                let h = 1e-7 * (1.0 + norm(*x));
                let mut pts = vec![*x];
                push_stencil(x, h, &mut pts);
                let v: Vec<f64> = pts.iter().map(|p| self.value(p)).collect();
                (
                    v[0],
                    [v[1] - v[2], v[3] - v[4], v[5] - v[6]].map(|d| d / (2.0 * h)),
                )
            }
        }
    }

    /// Bound of `F` over `cell` (see the module doc).
    pub fn bound(&self, cell: &Aabb) -> Bound {
        self.bound_with(cell, None)
    }

    /// [`Self::bound`], remembering field operands' bounds per box in `cache`.
    pub fn bound_with(&self, cell: &Aabb, cache: Option<&SignCache>) -> Bound {
        let (c, h) = (cell.center(), 0.5 * cell.diagonal());
        match self {
            Solid::Field(_) if cache.is_some() => {
                let key = (
                    std::ptr::from_ref::<Solid>(self) as usize,
                    [0, 1, 2, 3, 4, 5]
                        .map(|k| if k < 3 { cell.min[k] } else { cell.max[k - 3] }.to_bits()),
                );
                cached(&cache.unwrap_or_else(|| unreachable!()).bounds, key, || {
                    self.bound_with(cell, None)
                })
            }
            Solid::Field(m) => {
                let n = &m.normalization;
                let nc = Aabb {
                    min: n.forward(&cell.min),
                    max: n.forward(&cell.max),
                };
                if m.rbf.may_contain_zero(&nc) {
                    Bound::ANY
                } else if m.value(&c) > 0.0 {
                    Bound::INSIDE
                } else {
                    Bound::OUTSIDE
                }
            }
            Solid::Sphere(..) | Solid::Box(_) | Solid::Cylinder(..) | Solid::Torus(..) => {
                Bound::around(self.value(&c), h)
            }
            Solid::Union(a, b, al)
            | Solid::Intersection(a, b, al)
            | Solid::Difference(a, b, al) => {
                let (x, mut y) = (a.bound_with(cell, cache), b.bound_with(cell, cache));
                let f: fn(f64, f64, f64) -> f64 = match self {
                    Solid::Union(..) => r_union,
                    _ => r_intersection,
                };
                if matches!(self, Solid::Difference(..)) {
                    y = Bound {
                        lo: -y.hi,
                        hi: -y.lo,
                    };
                }
                Bound {
                    lo: f(x.lo, y.lo, *al),
                    hi: f(x.hi, y.hi, *al),
                }
            }
            Solid::Blend(a, b, a0) => {
                let (x, y) = (a.bound_with(cell, cache), b.bound_with(cell, cache));
                let ((mx, big_x), (my, big_y)) = (abs_range(x), abs_range(y));
                Bound {
                    lo: r_union(x.lo, y.lo, 0.0) + displacement(big_x, big_y, *a0),
                    hi: r_union(x.hi, y.hi, 0.0) + displacement(mx, my, *a0),
                }
            }
            Solid::Offset(a, d, _) => {
                let grown = a.bound_with(&cell.inflated(2.0 * d.abs()), cache);
                if grown.lo > 0.0 {
                    Bound::INSIDE
                } else if grown.hi < 0.0 {
                    Bound::OUTSIDE
                } else {
                    Bound::ANY
                }
            }
            Solid::Affine(a, map) => {
                let b = a.bound_with(&map.apply_box(cell), cache);
                let (p, q) = (map.gain * b.lo, map.gain * b.hi);
                Bound {
                    lo: p.min(q),
                    hi: p.max(q),
                }
            }
            Solid::Shared(a) => a.bound_with(cell, cache),
            Solid::Morph(a, b, t, _) => {
                let (x, y) = (a.bound_with(cell, cache), b.bound_with(cell, cache));
                let mix = |p: f64, q: f64| match (*t == 0.0, *t == 1.0) {
                    (true, _) => p,
                    (_, true) => q,
                    _ => (1.0 - t) * p + t * q,
                };
                Bound {
                    lo: mix(x.lo, y.lo),
                    hi: mix(x.hi, y.hi),
                }
            }
        }
    }

    /// A box (input units) outside which the solid has no inside: exact for primitives, set
    /// operations combine boxes, blends and offsets grow them. `None` when empty.
    pub fn bounds(&self) -> Option<Aabb> {
        let point = |c: Point3| Aabb { min: c, max: c };
        let b = match self {
            Solid::Field(m) => m.domain(),
            Solid::Sphere(c, r) => point(*c).inflated(*r),
            Solid::Box(b) => *b,
            Solid::Cylinder(a, b, r) => Aabb::from_points(&[*a, *b]).inflated(*r),
            Solid::Torus(c, big, small) => {
                let mut b = point(*c).inflated(big + small);
                b.min[2] = c[2] - small;
                b.max[2] = c[2] + small;
                b
            }
            Solid::Union(a, b, _) => union_box(a.bounds(), b.bounds())?,
            Solid::Intersection(a, b, _) => {
                let (p, q) = (a.bounds()?, b.bounds()?);
                let min = [0, 1, 2].map(|k| p.min[k].max(q.min[k]));
                let max = [0, 1, 2].map(|k| p.max[k].min(q.max[k]));
                if (0..3).any(|k| min[k] > max[k]) {
                    return None;
                }
                Aabb { min, max }
            }
            Solid::Difference(a, _, _) => a.bounds()?,
            Solid::Blend(a, b, a0) => union_box(a.bounds(), b.bounds())?.inflated(2.0 * a0),
            Solid::Offset(a, d, _) => a.bounds()?.inflated(2.0 * d.max(0.0)),
            Solid::Affine(a, map) => {
                let inv = Affine::inverse_of(map.m, map.t)?;
                inv.apply_box(&a.bounds()?)
            }
            Solid::Shared(a) => a.bounds()?,
            Solid::Morph(.., b) => *b,
        };
        (!b.is_empty()).then_some(b)
    }
}

/// Decisions of single-point sign-only evaluation per (operand, lattice box): the constant that
/// replaces an operand of fixed sign on the box, or `None` (evaluate it). Sharded maps shared by
/// the polygonizer's threads; a miss costs the operand's bound and one evaluation, a hit saves
/// one evaluation of the operand.
/// Also the bounds of field operands per box (the polygonizer asks for a tile's bound, then its
/// values; a field's bound costs ~10 evaluations far from its data).
#[derive(Default)]
pub struct SignCache {
    fixed: Sharded<(usize, [i64; 3]), Option<f64>>,
    bounds: Sharded<(usize, [u64; 6]), Bound>,
}

type Sharded<K, V> = [std::sync::Mutex<std::collections::HashMap<K, V>>; 16];

fn cached<K: std::hash::Hash + Eq, V: Copy>(
    shards: &Sharded<K, V>,
    key: K,
    make: impl FnOnce() -> V,
) -> V {
    use std::hash::{BuildHasher, BuildHasherDefault};
    let h =
        BuildHasherDefault::<std::collections::hash_map::DefaultHasher>::default().hash_one(&key);
    let shard = &shards[(h % 16) as usize];
    if let Some(v) = shard.lock().ok().and_then(|m| m.get(&key).copied()) {
        return v;
    }
    let v = make();
    if let Ok(mut m) = shard.lock() {
        m.insert(key, v);
    }
    v
}

impl SignCache {
    fn get_or(&self, key: (usize, [i64; 3]), make: impl FnOnce() -> Option<f64>) -> Option<f64> {
        cached(&self.fixed, key, make)
    }
}

/// The constant that may replace `s` on `region` (fixed sign), or `None`.
fn fixed_sign_value(s: &Solid, region: &Aabb, cache: Option<&SignCache>) -> Option<f64> {
    let b = s.bound_with(region, cache);
    if b.may_contain_zero() {
        return None;
    }
    let v = s.value(&region.center());
    // The bound's sign, should the centre's value round to 0.
    Some(if b.lo > 0.0 {
        v.max(f64::MIN_POSITIVE)
    } else {
        v.min(-f64::MIN_POSITIVE)
    })
}

impl Solid {
    /// `F(x)` with the same sign and zero set (see [`Solid::values_with`]): R-function operands of
    /// fixed sign on the lattice box `cell` (index `key`, edge `edge`) are replaced by a constant
    /// decided once per box in `cache`.
    pub fn value_sign_only(
        &self,
        x: &Point3,
        cell: &Aabb,
        key: [i64; 3],
        cache: &SignCache,
    ) -> f64 {
        match self {
            Solid::Union(a, b, al)
            | Solid::Intersection(a, b, al)
            | Solid::Difference(a, b, al) => {
                let mut v = [0.0; 2];
                for (o, s) in v.iter_mut().zip([a, b]) {
                    let id = std::ptr::from_ref::<Solid>(s) as usize;
                    *o = match cache.get_or((id, key), || fixed_sign_value(s, cell, Some(cache))) {
                        Some(c) => c,
                        None => s.value_sign_only(x, cell, key, cache),
                    };
                }
                match self {
                    Solid::Union(..) => r_union(v[0], v[1], *al),
                    Solid::Intersection(..) => r_intersection(v[0], v[1], *al),
                    _ => r_intersection(v[0], -v[1], *al),
                }
            }
            Solid::Shared(a) => a.value_sign_only(x, cell, key, cache),
            _ => self.value(x),
        }
    }
}

/// An R-function's operand at `points`: with `sign_only` and a fixed sign on `region`, its value
/// at the centre (see [`Solid::values_with`]); else evaluated.
fn operand(
    s: &Solid,
    region: &Aabb,
    points: &[Point3],
    out: &mut [f64],
    sign_only: Option<&SignCache>,
) {
    if sign_only.is_some()
        && let Some(v) = fixed_sign_value(s, region, sign_only)
    {
        out.fill(v);
        return;
    }
    s.values_with(region, points, out, sign_only);
}

fn union_box(a: Option<Aabb>, b: Option<Aabb>) -> Option<Aabb> {
    match (a, b) {
        (Some(mut p), Some(q)) => {
            p.grow(&q.min);
            p.grow(&q.max);
            Some(p)
        }
        (p, q) => p.or(q),
    }
}

/// The six points `x ± h e_k`, in the order +x, −x, +y, −y, +z, −z.
fn push_stencil(x: &Point3, h: f64, out: &mut Vec<Point3>) {
    for k in 0..3 {
        for s in [h, -h] {
            let mut p = *x;
            p[k] += s;
            out.push(p);
        }
    }
}

/// `v[0] / |∇|` with the gradient from the stencil values `v[1..7]`; `v[0]` where the gradient
/// vanishes.
fn normalised(v: &[f64], h: f64) -> f64 {
    let g = [v[1] - v[2], v[3] - v[4], v[5] - v[6]].map(|d| d / (2.0 * h));
    let n = norm(g);
    if n > 1e-12 { v[0] / n } else { v[0] }
}

/// A [`Solid`] seen by the polygonizer: rbfsurf's convention (`f < 0` inside) in a normalised
/// frame, `f(p) = −F(N⁻¹(p)) · s` for the similarity `N` (scale `s`) of the meshing domain.
pub struct SolidField<'a> {
    /// The solid.
    pub solid: &'a Solid,
    /// Input units ↔ the polygonizer's frame.
    pub frame: crate::geometry::Normalization,
    /// Edge of the lattice boxes on which single-point evaluations decide fixed-sign operands
    /// (the polygonizer's frame; 0 = always evaluate exactly).
    pub lattice: f64,
    /// Those decisions.
    pub cache: SignCache,
}

impl SolidField<'_> {
    fn to_input(&self, b: &Aabb) -> Aabb {
        Aabb {
            min: self.frame.inverse(&b.min),
            max: self.frame.inverse(&b.max),
        }
    }
}

impl ScalarField for SolidField<'_> {
    /// Sign-only (same signs and zero set as `F`, see [`Solid::value_sign_only`]): what the root
    /// refinement along grid edges needs.
    fn value(&self, p: &Point3) -> f64 {
        let x = self.frame.inverse(p);
        if self.lattice <= 0.0 {
            return -self.solid.value(&x) * self.frame.scale;
        }
        let key = p.map(|c| (c / self.lattice).floor() as i64);
        let lo = key.map(|k| k as f64 * self.lattice);
        let cell = self.to_input(&Aabb {
            min: lo,
            max: lo.map(|c| c + self.lattice),
        });
        -self.solid.value_sign_only(&x, &cell, key, &self.cache) * self.frame.scale
    }

    fn values_in(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        let pts: Vec<Point3> = points.iter().map(|p| self.frame.inverse(p)).collect();
        self.solid
            .values_with(&self.to_input(region), &pts, out, Some(&self.cache));
        for o in out.iter_mut() {
            *o = -*o * self.frame.scale;
        }
    }

    fn gradient(&self, p: &Point3) -> Point3 {
        // ∇_p [−F(N⁻¹ p) · s] = −∇F (N⁻¹ scales by 1/s).
        self.solid
            .value_gradient(&self.frame.inverse(p))
            .1
            .map(|c| -c)
    }

    fn may_contain_zero(&self, cell: &Aabb) -> bool {
        let cache = (self.lattice > 0.0).then_some(&self.cache);
        self.solid
            .bound_with(&self.to_input(cell), cache)
            .may_contain_zero()
    }
}
