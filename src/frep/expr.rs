//! The expression language (HyperFun-like, small):
//!
//! ```text
//! expr    := call | operand
//! call    := NAME '(' expr (',' expr)* ')'
//! operand := NUMBER | PATH | 'quoted path' | "quoted path"
//! ```
//!
//! A bare `PATH` is any run of characters other than spaces, commas, parentheses and quotes that is
//! not a number (`out/kitten.field`, `/data/a.field`); quote it otherwise. Relative paths are taken
//! from the base directory given to [`build`] (the working directory on the command line).
//! Operations (coordinates and lengths in the input's units, angles in degrees):
//! `sphere(cx, cy, cz, r)`, `box(x0, y0, z0, x1, y1, z1)`, `cylinder(x0, y0, z0, x1, y1, z1, r)`
//! (capped, axis between the two points), `torus(cx, cy, cz, R, r)` (around the z axis),
//! `union(a, b [, α])`, `intersection(a, b [, α])`, `difference(a, b [, α])` (R-functions,
//! `α ∈ (−1, 1]`, default 0), `blend(a, b, amount)`, `offset(a, d)`, `translate(a, x, y, z)`,
//! `scale(a, s)` (about the origin), `rotate(a, ax, ay, az, degrees)` (about the origin).

use super::ops::{Affine, Solid};
use super::{FieldModel, FrepError, format};
use crate::geometry::{Aabb, normalized};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A parsed expression (operands not yet loaded).
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// A number, with its column.
    Num(f64, usize),
    /// A field file path, with its column.
    Path(String, usize),
    /// An operation: name, arguments, column.
    Call(String, Vec<Expr>, usize),
}

impl Expr {
    fn column(&self) -> usize {
        match self {
            Expr::Num(_, c) | Expr::Path(_, c) | Expr::Call(_, _, c) => *c,
        }
    }

    /// Every field path the expression names, in order of appearance.
    pub fn paths(&self) -> Vec<&str> {
        match self {
            Expr::Path(p, _) => vec![p.as_str()],
            Expr::Num(..) => vec![],
            Expr::Call(_, args, _) => args.iter().flat_map(|a| a.paths()).collect(),
        }
    }
}

struct Parser<'a> {
    chars: Vec<(usize, char)>,
    at: usize,
    _src: &'a str,
}

fn syntax(message: impl Into<String>, column: usize) -> FrepError {
    FrepError::Syntax {
        message: message.into(),
        column,
    }
}

fn is_word(c: char) -> bool {
    !(c.is_whitespace() || matches!(c, ',' | '(' | ')' | '\'' | '"'))
}

impl Parser<'_> {
    fn skip_ws(&mut self) {
        while self.chars.get(self.at).is_some_and(|c| c.1.is_whitespace()) {
            self.at += 1;
        }
    }
    fn column(&self) -> usize {
        self.at + 1
    }
    fn peek(&mut self) -> Option<char> {
        self.skip_ws();
        self.chars.get(self.at).map(|c| c.1)
    }

    fn expr(&mut self) -> Result<Expr, FrepError> {
        let col = {
            self.skip_ws();
            self.column()
        };
        match self.peek() {
            None => Err(syntax("expected an operation, number or field path", col)),
            Some(q @ ('\'' | '"')) => {
                self.at += 1;
                let start = self.at;
                while self.chars.get(self.at).is_some_and(|c| c.1 != q) {
                    self.at += 1;
                }
                if self.at >= self.chars.len() {
                    return Err(syntax(format!("unterminated quote {q}"), col));
                }
                let s: String = self.chars[start..self.at].iter().map(|c| c.1).collect();
                self.at += 1;
                Ok(Expr::Path(s, col))
            }
            Some(c) if is_word(c) => {
                let start = self.at;
                while self.chars.get(self.at).is_some_and(|c| is_word(c.1)) {
                    self.at += 1;
                }
                let word: String = self.chars[start..self.at].iter().map(|c| c.1).collect();
                if self.peek() == Some('(') {
                    self.at += 1;
                    let args = self.args(col)?;
                    return Ok(Expr::Call(word, args, col));
                }
                match word.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(Expr::Num(v, col)),
                    Ok(_) => Err(syntax(format!("{word} is not a finite number"), col)),
                    Err(_) => Ok(Expr::Path(word, col)),
                }
            }
            Some(c) => Err(syntax(format!("unexpected '{c}'"), col)),
        }
    }

    fn args(&mut self, open_col: usize) -> Result<Vec<Expr>, FrepError> {
        let mut args = Vec::new();
        if self.peek() == Some(')') {
            self.at += 1;
            return Ok(args);
        }
        loop {
            args.push(self.expr()?);
            match self.peek() {
                Some(',') => self.at += 1,
                Some(')') => {
                    self.at += 1;
                    return Ok(args);
                }
                Some(c) => {
                    return Err(syntax(
                        format!("expected ',' or ')', found '{c}'"),
                        self.column(),
                    ));
                }
                None => {
                    return Err(syntax(
                        format!("missing ')' for the '(' opened at column {open_col}"),
                        self.column(),
                    ));
                }
            }
        }
    }
}

/// Parse `src`.
pub fn parse(src: &str) -> Result<Expr, FrepError> {
    let mut p = Parser {
        chars: src.char_indices().collect(),
        at: 0,
        _src: src,
    };
    let e = p.expr()?;
    if let Some(c) = p.peek() {
        return Err(syntax(
            format!("unexpected '{c}' after the expression"),
            p.column(),
        ));
    }
    Ok(e)
}

/// Loads each field file once.
pub struct Loader {
    base: PathBuf,
    cache: HashMap<PathBuf, Arc<FieldModel>>,
    files: bool,
}

impl Loader {
    /// Relative paths are resolved against `base`.
    pub fn new(base: &Path) -> Self {
        Loader {
            base: base.to_path_buf(),
            cache: HashMap::new(),
            files: true,
        }
    }

    /// A loader that never reads files: only names given to [`Self::insert`] resolve (the HTTP
    /// service, whose operands are job ids).
    pub fn preloaded_only() -> Self {
        Loader {
            base: PathBuf::new(),
            cache: HashMap::new(),
            files: false,
        }
    }

    /// Pre-load `model` under `name` (the HTTP service names fields by job id).
    pub fn insert(&mut self, name: &str, model: Arc<FieldModel>) {
        self.cache.insert(self.base.join(name), model);
    }

    fn load(&mut self, p: &str) -> Result<Arc<FieldModel>, FrepError> {
        let path = self.base.join(p);
        if let Some(m) = self.cache.get(&path) {
            return Ok(Arc::clone(m));
        }
        if !self.files {
            return Err(FrepError::Read {
                path: p.to_string(),
                message: "not a known operand".into(),
            });
        }
        let m = Arc::new(format::read(&path)?);
        self.cache.insert(path, Arc::clone(&m));
        Ok(m)
    }
}

/// Resolve `e` into a solid, loading field files with `loader`.
pub fn build(e: &Expr, loader: &mut Loader) -> Result<Solid, FrepError> {
    match e {
        Expr::Path(p, _) => Ok(Solid::Field(loader.load(p)?)),
        Expr::Num(v, col) => Err(syntax(
            format!("a number ({v}) where a solid is expected"),
            *col,
        )),
        Expr::Call(name, args, col) => build_call(name, args, *col, loader),
    }
}

/// `(solids, allowed numbers of numeric arguments, description)` of an operation.
fn signature(name: &str) -> Option<(usize, &'static [usize], &'static str)> {
    Some(match name {
        "sphere" => (0, &[4], "4 numbers (cx, cy, cz, r)"),
        "box" => (0, &[6], "6 numbers (x0, y0, z0, x1, y1, z1)"),
        "cylinder" => (0, &[7], "7 numbers (x0, y0, z0, x1, y1, z1, r)"),
        "torus" => (0, &[5], "5 numbers (cx, cy, cz, R, r)"),
        "union" | "intersection" | "difference" => (2, &[0, 1], "2 solids and an optional α"),
        "blend" => (2, &[1], "2 solids and an amount"),
        "offset" => (1, &[1], "a solid and a distance"),
        "translate" => (1, &[3], "a solid and 3 numbers"),
        "scale" => (1, &[1], "a solid and a factor"),
        "rotate" => (1, &[4], "a solid, an axis (3 numbers) and degrees"),
        _ => return None,
    })
}

/// Check the arguments against the operation's signature; build the solid operands and collect
/// the numbers.
fn arguments(
    name: &str,
    args: &[Expr],
    col: usize,
    loader: &mut Loader,
) -> Result<(Vec<Solid>, Vec<f64>), FrepError> {
    let (solids, nums, expected) = signature(name).ok_or_else(|| FrepError::UnknownOperation {
        name: name.to_string(),
        column: col,
    })?;
    let arity = |got: String| FrepError::Arity {
        name: name.to_string(),
        column: col,
        expected,
        got,
    };
    if args.len() < solids || !nums.contains(&(args.len() - solids)) {
        return Err(arity(format!("{} argument(s)", args.len())));
    }
    let mut children = Vec::with_capacity(solids);
    for a in &args[..solids] {
        if let Expr::Num(v, _) = a {
            return Err(arity(format!("the number {v} where a solid is expected")));
        }
        children.push(build(a, loader)?);
    }
    let mut n = Vec::with_capacity(args.len() - solids);
    for a in &args[solids..] {
        match a {
            Expr::Num(v, _) => n.push(*v),
            other => {
                return Err(arity(format!(
                    "a solid at column {} where a number is expected",
                    other.column()
                )));
            }
        }
    }
    Ok((children, n))
}

fn build_call(
    name: &str,
    args: &[Expr],
    col: usize,
    loader: &mut Loader,
) -> Result<Solid, FrepError> {
    let (children, n) = arguments(name, args, col, loader)?;
    let bad = |message: String| FrepError::BadArgument {
        name: name.to_string(),
        column: col,
        message,
    };
    let positive = |v: f64, what: &str| {
        if v > 0.0 {
            Ok(v)
        } else {
            Err(bad(format!("{what} must be positive, got {v}")))
        }
    };
    let mut kids = children.into_iter();
    let mut next = || Box::new(kids.next().expect("arity checked"));
    match name {
        "sphere" => Some(Solid::Sphere(
            [n[0], n[1], n[2]],
            positive(n[3], "the radius")?,
        )),
        "box" => {
            let b = Aabb::from_points(&[[n[0], n[1], n[2]], [n[3], n[4], n[5]]]);
            if b.extent().iter().any(|&e| e <= 0.0) {
                return Err(bad("the box has no volume".into()));
            }
            Some(Solid::Box(b))
        }
        "cylinder" => {
            let (a, b) = ([n[0], n[1], n[2]], [n[3], n[4], n[5]]);
            if a == b {
                return Err(bad("the axis end points coincide".into()));
            }
            Some(Solid::Cylinder(a, b, positive(n[6], "the radius")?))
        }
        "torus" => {
            let (big, small) = (positive(n[3], "R")?, positive(n[4], "r")?);
            Some(Solid::Torus([n[0], n[1], n[2]], big, small))
        }
        "union" | "intersection" | "difference" => {
            let alpha = n.first().copied().unwrap_or(0.0);
            if !(alpha > -1.0 && alpha <= 1.0) {
                return Err(bad(format!("α must be in (-1, 1], got {alpha}")));
            }
            let (a, b) = (next(), next());
            Some(match name {
                "union" => Solid::Union(a, b, alpha),
                "intersection" => Solid::Intersection(a, b, alpha),
                _ => Solid::Difference(a, b, alpha),
            })
        }
        "blend" => {
            let (a, b) = (next(), next());
            Some(Solid::Blend(a, b, positive(n[0], "the amount")?))
        }
        "offset" => {
            let a = next();
            let size = a.bounds().map_or(1.0, |b| b.diagonal());
            Some(Solid::Offset(a, n[0], 1e-4 * size))
        }
        "translate" => affine(next(), IDENTITY, [n[0], n[1], n[2]], 1.0),
        "scale" => {
            let s = positive(n[0], "the factor")?;
            if !(1e-12..=1e12).contains(&s) {
                return Err(bad(format!("the factor must be in [1e-12, 1e12], got {s}")));
            }
            affine(
                next(),
                [[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]],
                [0.0; 3],
                s,
            )
        }
        _ => {
            let axis =
                normalized([n[0], n[1], n[2]]).ok_or_else(|| bad("the axis is zero".into()))?;
            affine(next(), rotation(axis, n[3].to_radians()), [0.0; 3], 1.0)
        }
    }
    .ok_or_else(|| bad("the map is not invertible".into()))
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The solid moved by the forward map `x ↦ m x + t`, values multiplied by `gain`.
fn affine(child: Box<Solid>, m: [[f64; 3]; 3], t: [f64; 3], gain: f64) -> Option<Solid> {
    let mut inv = Affine::inverse_of(m, t)?;
    inv.gain = gain;
    Some(Solid::Affine(child, inv))
}

/// Rotation by `angle` radians about the unit `axis` (Rodrigues).
pub fn rotation(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}
