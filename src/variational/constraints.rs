//! Constraint vocabulary shared by every variational method (2D curves and 3D surfaces), their
//! validation, and the module's error type.
//!
//! A [`Sample`] is what a user gives: a point, an optional outward normal and a field value
//! (0 on the curve/surface, negative inside, positive outside — the crate's convention `f < 0`
//! inside; the seeds use `+1` for interior points, which is `−1` here). Methods turn samples
//! into [`ValueConstraint`]s (pseudo-normal offset points, Turk & O'Brien 2002) or use the
//! normals directly (true normals, Shen 2007 / Hermite interpolation).
//!
//! Validation is `O(n log n)` on average (sort-and-sweep for coincident points) plus `O(n·d²)`
//! for the affine-rank test. Reference: Mann, *A Study of Two Implicit Data Interpolation
//! Schemes*, Waterloo CS-2013-09, §2–3.

use crate::geometry::{dist2, dot, sub};
use thiserror::Error;

/// Errors of the variational fits, the curve workbench and the curve file reader.
/// Rows are 0-based indices into the sample list (for files: data lines, comments excluded).
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum VariationalError {
    /// A coordinate, normal component or value is NaN or infinite.
    #[error("row {row}: {what} is not a finite number; fix or remove the row")]
    NonFinite {
        /// Offending row.
        row: usize,
        /// Which field ("coordinate", "normal", "value").
        what: &'static str,
    },
    /// A normal of zero length was given.
    #[error("row {row}: the normal has zero length; give a non-zero normal or none")]
    ZeroNormal {
        /// Offending row.
        row: usize,
    },
    /// Two constraints at the same place ask for different values (e.g. an interior point on the curve).
    #[error(
        "rows {first} and {second} are at the same point but ask for values {first_value} and {second_value}; move or remove one"
    )]
    ConflictingValues {
        /// First row.
        first: usize,
        /// Second row.
        second: usize,
        /// Value asked by the first row.
        first_value: f64,
        /// Value asked by the second row.
        second_value: f64,
    },
    /// Two constraints at the same place with the same value (the dense system would be singular).
    #[error("rows {first} and {second} are the same point; remove the duplicate")]
    DuplicatePoint {
        /// First row.
        first: usize,
        /// Second row.
        second: usize,
    },
    /// A generated pseudo-normal point landed on another constraint.
    #[error(
        "the pseudo-normal point of row {row} coincides with the constraint of row {other}; reduce the normal offset"
    )]
    OffsetCollision {
        /// Row whose offset point collides.
        row: usize,
        /// Row it collides with.
        other: usize,
    },
    /// Fewer distinct constraint points than the linear polynomial needs.
    #[error(
        "{got} constraint points, the linear polynomial in {dim}D needs at least {needed}; add points"
    )]
    TooFewPoints {
        /// Points given.
        got: usize,
        /// Points needed (dimension + 1).
        needed: usize,
        /// Dimension.
        dim: usize,
    },
    /// All points lie in a lower-dimensional affine subspace (collinear in 2D, coplanar in 3D).
    #[error(
        "all constraint points lie in a {affine_dim}-dimensional affine subspace (spanned from rows {rows:?}); the linear polynomial is not determined — add a point off it"
    )]
    Degenerate {
        /// Affine dimension found (1 = collinear).
        affine_dim: usize,
        /// Rows spanning that subspace.
        rows: Vec<usize>,
    },
    /// Every value is zero and no normal is given: the only interpolant is `f ≡ 0`.
    #[error(
        "all values are zero and there are no normals: f ≡ 0 fits; give normals or interior/exterior points"
    )]
    TrivialData,
    /// The method needs normals but a row has none.
    #[error("row {row} has no normal but the method needs one on every on-curve point")]
    MissingNormal {
        /// Offending row.
        row: usize,
    },
    /// Points and normals have different lengths.
    #[error("{points} points but {normals} normals; give one normal per point")]
    LengthMismatch {
        /// Number of points.
        points: usize,
        /// Number of normals.
        normals: usize,
    },
    /// The dense system is singular to working precision.
    #[error(
        "the {n}×{n} system is singular (reciprocal condition estimate {rcond:.3e}); remove nearly coincident or degenerate constraints"
    )]
    SingularSystem {
        /// System size.
        n: usize,
        /// Reciprocal 1-norm condition estimate.
        rcond: f64,
    },
    /// The dense system would be too large for the configured limit.
    #[error(
        "the dense system would have {unknowns} unknowns, above the limit {max}; use the CSRBF method"
    )]
    TooLarge {
        /// Unknowns requested.
        unknowns: usize,
        /// Configured limit.
        max: usize,
    },
    /// A parameter is out of range.
    #[error("parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Given value.
        value: f64,
        /// What is allowed.
        reason: &'static str,
    },
    /// A curve text file could not be parsed.
    #[error("line {line}: {message}")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What was wrong.
        message: String,
    },
    /// The caller cancelled the work through its progress handle.
    #[error("cancelled")]
    Cancelled,
    /// The dense solver failed otherwise.
    #[error(transparent)]
    Solver(crate::linalg::LinalgError),
    /// Network training produced a non-finite loss or gradient.
    #[error("training diverged at epoch {epoch} (non-finite loss); lower the learning rate or λ")]
    TrainingDiverged {
        /// Epoch at which the loss became non-finite.
        epoch: usize,
    },
    /// An unknown built-in data set name.
    #[error("unknown data set {name:?}; known: {known}")]
    UnknownDataset {
        /// Name asked for.
        name: String,
        /// Comma-separated list of known names.
        known: String,
    },
}

impl From<crate::linalg::LinalgError> for VariationalError {
    fn from(e: crate::linalg::LinalgError) -> Self {
        match e {
            crate::linalg::LinalgError::SingularDense { n, rcond } => {
                VariationalError::SingularSystem { n, rcond }
            }
            crate::linalg::LinalgError::Cancelled => VariationalError::Cancelled,
            other => VariationalError::Solver(other),
        }
    }
}

impl VariationalError {
    /// The 0-based sample rows the error names (empty when it names none); a front end maps them
    /// to file lines.
    pub fn rows(&self) -> Vec<usize> {
        use VariationalError as E;
        match self {
            E::NonFinite { row, .. } | E::ZeroNormal { row, .. } | E::MissingNormal { row, .. } => {
                vec![*row]
            }
            E::ConflictingValues { first, second, .. } | E::DuplicatePoint { first, second } => {
                vec![*first, *second]
            }
            E::OffsetCollision { row, other } => vec![*row, *other],
            E::Degenerate { rows, .. } => rows.clone(),
            _ => Vec::new(),
        }
    }
}

/// One user constraint in `D` dimensions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample<const D: usize> {
    /// Position (input units).
    pub p: [f64; D],
    /// Outward normal (any non-zero length; normalised internally), if known.
    pub normal: Option<[f64; D]>,
    /// Field value asked for: 0 on the curve, `< 0` interior, `> 0` exterior; `|value|` is the weight.
    pub value: f64,
}

impl<const D: usize> Sample<D> {
    /// An on-curve point (value 0) with an optional normal.
    pub fn on_curve(p: [f64; D], normal: Option<[f64; D]>) -> Self {
        Sample {
            p,
            normal,
            value: 0.0,
        }
    }

    /// The kind of constraint this sample is.
    pub fn kind(&self) -> PointKind {
        if self.value == 0.0 {
            PointKind::OnCurve
        } else if self.value < 0.0 {
            PointKind::Interior
        } else {
            PointKind::Exterior
        }
    }
}

/// What a value constraint stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PointKind {
    /// `f = 0`: a data point on the curve/surface.
    OnCurve,
    /// `f < 0`: a point inside.
    Interior,
    /// `f > 0`: a point outside.
    Exterior,
}

/// Where a value constraint came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// The sample of this row itself.
    Sample(usize),
    /// A pseudo-normal point generated from the sample of `row`, outside (`+`) or inside (`−`).
    PseudoNormal {
        /// Row of the sample.
        row: usize,
        /// `true` when offset along `+n` (outside).
        outside: bool,
    },
}

impl Origin {
    /// The sample row this constraint traces back to.
    pub fn row(&self) -> usize {
        match *self {
            Origin::Sample(r) | Origin::PseudoNormal { row: r, .. } => r,
        }
    }
}

/// `f(p) = value`, the unit of every dense system and every MLS sum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueConstraint<const D: usize> {
    /// Position.
    pub p: [f64; D],
    /// Value asked for.
    pub value: f64,
    /// Where it came from (for error messages and plots).
    pub origin: Origin,
}

/// How far pseudo-normal points sit from their data point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Offset {
    /// This fraction of the median nearest-neighbour spacing of the on-curve points (default 0.1).
    /// Relative to the spacing, it avoids the extra sheet Mann saw with Turk & O'Brien's fixed 0.01
    /// on K4; 0.1 rather than Mann's 1/3 because outward-only points at 1/3 leave small spurious
    /// loops at the concave Koch vertices (see the Turk–O'Brien tests).
    SpacingFraction(f64),
    /// A fixed distance in normalised units (longest bbox edge = 1); Turk & O'Brien use 0.01.
    Normalized(f64),
}

/// Which side(s) of the data point get a pseudo-normal point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sides {
    /// One point at `p + δn` with value `+δ` (Turk & O'Brien).
    Outside,
    /// One point at `p − δn` with value `−δ`.
    Inside,
    /// Both (Shen's MLS needs values of both signs).
    Both,
}

/// Pseudo-normal constraint placement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PseudoNormalParams {
    /// Distance of the offset points (default `SpacingFraction(0.1)`).
    pub offset: Offset,
    /// Sides (default `Outside`).
    pub sides: Sides,
}

impl Default for PseudoNormalParams {
    fn default() -> Self {
        PseudoNormalParams {
            offset: Offset::SpacingFraction(0.1),
            sides: Sides::Outside,
        }
    }
}

/// Check every sample for NaN/∞, zero normals and conflicting duplicates.
pub fn validate_samples<const D: usize>(samples: &[Sample<D>]) -> Result<(), VariationalError> {
    for (row, s) in samples.iter().enumerate() {
        if s.p.iter().any(|c| !c.is_finite()) {
            return Err(VariationalError::NonFinite {
                row,
                what: "coordinate",
            });
        }
        if !s.value.is_finite() {
            return Err(VariationalError::NonFinite { row, what: "value" });
        }
        if let Some(n) = s.normal {
            if n.iter().any(|c| !c.is_finite()) {
                return Err(VariationalError::NonFinite {
                    row,
                    what: "normal",
                });
            }
            if n.iter().all(|&c| c == 0.0) {
                return Err(VariationalError::ZeroNormal { row });
            }
        }
    }
    let vc: Vec<ValueConstraint<D>> = samples
        .iter()
        .enumerate()
        .map(|(row, s)| ValueConstraint {
            p: s.p,
            value: s.value,
            origin: Origin::Sample(row),
        })
        .collect();
    check_coincident(&vc)?;
    if samples.iter().all(|s| s.value == 0.0 && s.normal.is_none()) {
        return Err(VariationalError::TrivialData);
    }
    Ok(())
}

/// Per-axis minimum and maximum of a point list (±inf for no points).
pub fn bounds<const D: usize>(pts: impl Iterator<Item = [f64; D]>) -> ([f64; D], [f64; D]) {
    let mut lo = [f64::INFINITY; D];
    let mut hi = [f64::NEG_INFINITY; D];
    for p in pts {
        for k in 0..D {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Largest bounding-box edge of a point list (0 for fewer than two points).
pub fn extent<const D: usize>(pts: impl Iterator<Item = [f64; D]>) -> f64 {
    let (lo, hi) = bounds(pts);
    (0..D).map(|k| hi[k] - lo[k]).fold(0.0, f64::max).max(0.0)
}

/// Error when two constraints are closer than `1e-12 ×` the data extent.
/// Sort-and-sweep along x: `O(n log n)` unless many points share an x.
pub fn check_coincident<const D: usize>(c: &[ValueConstraint<D>]) -> Result<(), VariationalError> {
    let tol = 1e-12 * extent(c.iter().map(|v| v.p)).max(f64::MIN_POSITIVE);
    let mut order: Vec<usize> = (0..c.len()).collect();
    order.sort_by(|&a, &b| c[a].p[0].total_cmp(&c[b].p[0]).then(a.cmp(&b)));
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if c[j].p[0] - c[i].p[0] > tol {
                break;
            }
            if dist2(c[i].p, c[j].p) <= tol * tol {
                return Err(coincidence_error(&c[i.min(j)], &c[i.max(j)]));
            }
        }
    }
    Ok(())
}

fn coincidence_error<const D: usize>(
    a: &ValueConstraint<D>,
    b: &ValueConstraint<D>,
) -> VariationalError {
    match (a.origin, b.origin) {
        (Origin::PseudoNormal { row, .. }, o) | (o, Origin::PseudoNormal { row, .. }) => {
            VariationalError::OffsetCollision {
                row,
                other: o.row(),
            }
        }
        _ if a.value != b.value => VariationalError::ConflictingValues {
            first: a.origin.row(),
            second: b.origin.row(),
            first_value: a.value,
            second_value: b.value,
        },
        _ => VariationalError::DuplicatePoint {
            first: a.origin.row(),
            second: b.origin.row(),
        },
    }
}

/// Error unless the points contain `D + 1` affinely independent ones (so the linear polynomial
/// block has full rank). Greedy Gram–Schmidt with tolerance `1e-9 ×` extent: `O(n·D²)`.
pub fn check_affine_rank<const D: usize>(
    pts: &[[f64; D]],
    rows: &[usize],
) -> Result<(), VariationalError> {
    if pts.len() < D + 1 {
        return Err(VariationalError::TooFewPoints {
            got: pts.len(),
            needed: D + 1,
            dim: D,
        });
    }
    let tol = 1e-9 * extent(pts.iter().copied());
    let mut basis: Vec<[f64; D]> = Vec::with_capacity(D);
    let mut used = vec![rows[0]];
    for (k, p) in pts.iter().enumerate().skip(1) {
        let mut v = sub(*p, pts[0]);
        for b in &basis {
            let d = dot(v, *b);
            for (x, y) in v.iter_mut().zip(b) {
                *x -= d * y;
            }
        }
        let len = dot(v, v).sqrt();
        if len > tol {
            basis.push(v.map(|x| x / len));
            used.push(rows[k]);
            if basis.len() == D {
                return Ok(());
            }
        }
    }
    Err(VariationalError::Degenerate {
        affine_dim: basis.len(),
        rows: used,
    })
}

/// Median over on-curve samples of the distance to the nearest other on-curve sample
/// (brute force `O(n²)`, fine for the sizes a dense method can take).
pub fn median_spacing<const D: usize>(pts: &[[f64; D]]) -> f64 {
    use rayon::prelude::*;
    if pts.len() < 2 {
        return 0.0;
    }
    let mut nn: Vec<f64> = pts
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            pts.iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| dist2(*p, *q))
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .collect();
    nn.sort_by(f64::total_cmp);
    nn[nn.len() / 2]
}

/// Unit vector of `n` (caller guarantees non-zero length).
pub fn unit<const D: usize>(n: &[f64; D]) -> [f64; D] {
    let l = dot(*n, *n).sqrt();
    n.map(|x| x / l)
}

/// Turn samples into value constraints: each sample itself plus, for samples with a normal,
/// pseudo-normal points at `p ± δ n̂` with values `±δ` (`δ` in the samples' units; `δ` from
/// `params.offset` with `unit_length` = the length of one normalised unit).
pub fn expand_pseudo_normals<const D: usize>(
    samples: &[Sample<D>],
    params: &PseudoNormalParams,
    unit_length: f64,
) -> Result<Vec<ValueConstraint<D>>, VariationalError> {
    let delta = offset_distance(samples, &params.offset, unit_length)?;
    let mut out = Vec::with_capacity(samples.len() * 2);
    for (row, s) in samples.iter().enumerate() {
        out.push(ValueConstraint {
            p: s.p,
            value: s.value,
            origin: Origin::Sample(row),
        });
        let Some(n) = s.normal else { continue };
        let n = unit(&n);
        let sides: &[bool] = match params.sides {
            Sides::Outside => &[true],
            Sides::Inside => &[false],
            Sides::Both => &[true, false],
        };
        for &outside in sides {
            let sgn = if outside { 1.0 } else { -1.0 };
            let p = std::array::from_fn(|k| s.p[k] + sgn * delta * n[k]);
            out.push(ValueConstraint {
                p,
                value: s.value + sgn * delta,
                origin: Origin::PseudoNormal { row, outside },
            });
        }
    }
    check_coincident(&out)?;
    Ok(out)
}

/// The pseudo-normal distance `δ` in the samples' units.
pub fn offset_distance<const D: usize>(
    samples: &[Sample<D>],
    offset: &Offset,
    unit_length: f64,
) -> Result<f64, VariationalError> {
    let (name, v) = match *offset {
        Offset::SpacingFraction(f) => ("offset spacing fraction", f),
        Offset::Normalized(d) => ("offset distance", d),
    };
    if !(v.is_finite() && v > 0.0) {
        return Err(VariationalError::InvalidParameter {
            name,
            value: v,
            reason: "must be > 0",
        });
    }
    Ok(match *offset {
        Offset::SpacingFraction(f) => {
            let on: Vec<[f64; D]> = samples
                .iter()
                .filter(|s| s.value == 0.0)
                .map(|s| s.p)
                .collect();
            let sp = median_spacing(&on);
            if sp > 0.0 { f * sp } else { f * unit_length }
        }
        Offset::Normalized(d) => d * unit_length,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(x: f64, y: f64, v: f64) -> Sample<2> {
        Sample {
            p: [x, y],
            normal: None,
            value: v,
        }
    }

    #[test]
    fn nan_names_row() {
        let d = [s(0.0, 0.0, 0.0), s(1.0, 0.0, 0.0), s(f64::NAN, 1.0, 0.0)];
        assert_eq!(
            validate_samples(&d),
            Err(VariationalError::NonFinite {
                row: 2,
                what: "coordinate"
            })
        );
    }

    #[test]
    fn interior_point_on_curve_names_rows() {
        let d = [
            s(0.0, 0.0, 0.0),
            s(1.0, 0.0, 0.0),
            s(0.5, 1.0, 0.0),
            s(1.0, 0.0, -1.0),
        ];
        let e = validate_samples(&d).unwrap_err();
        assert!(
            matches!(
                e,
                VariationalError::ConflictingValues {
                    first: 1,
                    second: 3,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("rows 1 and 3"));
    }

    #[test]
    fn collinear_is_degenerate() {
        let pts = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]];
        let e = check_affine_rank(&pts, &[0, 1, 2, 3]).unwrap_err();
        assert_eq!(
            e,
            VariationalError::Degenerate {
                affine_dim: 1,
                rows: vec![0, 1]
            }
        );
        let e = check_affine_rank(&pts[..2], &[0, 1]).unwrap_err();
        assert!(matches!(
            e,
            VariationalError::TooFewPoints {
                got: 2,
                needed: 3,
                dim: 2
            }
        ));
        check_affine_rank(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.1]], &[0, 1, 2]).unwrap();
    }

    #[test]
    fn all_zero_without_normals_is_trivial() {
        let d = [s(0.0, 0.0, 0.0), s(1.0, 0.0, 0.0), s(0.5, 1.0, 0.0)];
        assert_eq!(validate_samples(&d), Err(VariationalError::TrivialData));
    }

    #[test]
    fn pseudo_normals_use_median_spacing() {
        let d: Vec<Sample<2>> = (0..4)
            .map(|k| {
                let a = k as f64 * std::f64::consts::FRAC_PI_2;
                Sample::on_curve([a.cos(), a.sin()], Some([2.0 * a.cos(), 2.0 * a.sin()]))
            })
            .collect();
        let p = PseudoNormalParams {
            sides: Sides::Both,
            ..Default::default()
        };
        let p = PseudoNormalParams {
            offset: Offset::SpacingFraction(1.0 / 3.0),
            ..p
        };
        let c = expand_pseudo_normals(&d, &p, 1.0).unwrap();
        assert_eq!(c.len(), 12);
        let delta = 2f64.sqrt() / 3.0;
        assert!((c[1].p[0] - (1.0 + delta)).abs() < 1e-12 && (c[1].value - delta).abs() < 1e-12);
        assert!((c[2].p[0] - (1.0 - delta)).abs() < 1e-12 && (c[2].value + delta).abs() < 1e-12);
    }
}
