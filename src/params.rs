//! Reconstruction parameters: one definition shared by the library, the command line, the HTTP API
//! and the report. Defaults live only in [`ReconParams::default`].

// The types of the parameters' fields, re-exported so that a caller names every parameter
// through this module.
pub use crate::clean::{CleanParams, OutlierParams};
pub use crate::linalg::SolverKind;
pub use crate::ordering::OrderingKind;
pub use crate::rbf::{CarrierKind, CarrierParams, Kernel, LocalFit, Support};
pub use crate::spatial::IndexKind;

/// Optional polynomial part of the spline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Polynomial {
    /// No polynomial: `A λ = r` (symmetric positive definite).
    #[default]
    None,
    /// `p = v₀ + v·x`: the doubly bordered system, solved block-wise (George & Liu).
    Linear,
}

impl std::str::FromStr for Polynomial {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => Ok(Polynomial::None),
            "linear" => Ok(Polynomial::Linear),
            _ => Err(format!("unknown polynomial '{s}' (use none or linear)")),
        }
    }
}

impl std::fmt::Display for Polynomial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Polynomial::None => "none",
            Polynomial::Linear => "linear",
        })
    }
}

/// Which implicit fit to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Carrier + compactly supported Wendland spline (sparse; scales to large N).
    #[default]
    Csrbf,
    /// Turk–O'Brien variational implicit (`r³`, dense; refused above 12,000 unknowns ≈ 6,000 points, practical up to ~2–3k).
    Variational,
    /// Shen's MLS implicit (linear basis, true normals; `O(N)` per evaluation).
    Mls,
}

impl Method {
    /// Command-line / report name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Csrbf => "csrbf",
            Method::Variational => "variational",
            Method::Mls => "mls",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [Method::Csrbf, Method::Variational, Method::Mls]
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown method '{s}' (use csrbf, variational or mls)"))
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What to do with surface the data does not support (farther than the support radius from every point).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Boundary {
    /// `trim` with the local carrier (its sheets beyond the data are extrapolation), `closed` with a
    /// sphere or ellipsoid carrier (the seed's closed solid).
    #[default]
    Auto,
    /// Drop unsupported triangles: open scans stay open, with boundary loops in the report.
    Trim,
    /// Keep everything: the carrier closes the surface.
    Closed,
}

impl std::str::FromStr for Boundary {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Boundary::Auto),
            "trim" => Ok(Boundary::Trim),
            "closed" => Ok(Boundary::Closed),
            _ => Err(format!("unknown boundary '{s}' (use auto, trim or closed)")),
        }
    }
}

impl std::fmt::Display for Boundary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Boundary::Auto => "auto",
            Boundary::Trim => "trim",
            Boundary::Closed => "closed",
        })
    }
}

/// Everything that steers a reconstruction.
#[derive(Debug, Clone, PartialEq)]
pub struct ReconParams {
    /// Implicit fit (default `csrbf`).
    pub method: Method,
    /// Wendland kernel (default `wendland-c2`).
    pub kernel: Kernel,
    /// Support radius or target neighbour count (default 30 neighbours).
    pub support: Support,
    /// Carrier solid (default `auto`: local tangent planes with normals, else ellipsoid).
    pub carrier: CarrierParams,
    /// Spatial index for neighbour queries (default: the faster in the `spatial` bench).
    pub index: IndexKind,
    /// Octree leaf size K (seed Algorithm I), default 16.
    pub leaf_size: usize,
    /// Matrix ordering (default `bfs`, the seed's Algorithm III: as tight as RCM here and ~7× faster; used by the envelope solver and reported for all).
    pub ordering: OrderingKind,
    /// Linear solver (default `auto`: faer supernodal Cholesky with AMD when its factor fits the
    /// memory budget, else conjugate gradients).
    pub solver: SolverKind,
    /// Polynomial part (default none).
    pub polynomial: Polynomial,
    /// Marching grid cells along the longest axis; `None` chooses from the point spacing (64–200).
    pub resolution: Option<usize>,
    /// Input cleaning.
    pub clean: CleanParams,
    /// Memory budget for the matrix and its factor, MiB (default 8192). Bigger systems are refused
    /// before allocation, with an estimate.
    pub max_memory_mib: u64,
    /// Smoothing λ added to the matrix diagonal: `(A + λI) λ = r` approximates instead of
    /// interpolating. Default `auto`: chosen from the measured noise (0 on clean data, see
    /// [`crate::rbf::noise`]).
    pub smoothing: Smoothing,
    /// Statistical outlier removal before fitting (default off).
    pub outliers: Option<OutlierParams>,
    /// Unsupported surface: trim or keep (default `auto`).
    pub boundary: Boundary,
    /// CSRBF levels, coarse to fine, each halving the support radius (default 1: the seed's single
    /// level; more levels adapt to uneven density at ~2.5× the evaluation cost).
    pub levels: usize,
    /// Block decomposition with a partition of unity (default `auto`: one system up to 250,000
    /// points, blocks of at most 250,000 points above).
    pub blocks: crate::rbf::Blocks,
    /// Drop connected components with fewer triangles than this fraction of the largest one
    /// (default 0 = keep every component; 0.01 removes floaters left by noise and outliers).
    pub min_component: f64,
    /// Drop floaters: connected components carried by fewer than this fraction of the data points
    /// (each point counts for the component of its nearest mesh vertex within the support radius).
    /// Default 0.01; 0 keeps every component. Two separate objects each carry their own points and
    /// both stay.
    pub min_support: f64,
    /// Cut handles whose shortest non-separating loop is at most this many support radii long
    /// (default 2; 0 keeps every handle): thin bridges and pinholes where two parts come closer
    /// than the data separate them ([`crate::mesh::handles`]). Closed surfaces only.
    pub max_handle_loop: f64,
    /// How far an open surface's border may reach beyond its data, in support radii (default
    /// 0.5; 1 keeps the trim's border). The trim keeps every triangle within one support radius of
    /// a point, which bridges gaps between returns but lets the border overhang the data; the
    /// border is then peeled back to this distance wherever that keeps the pieces, holes and
    /// handles ([`crate::mesh::peel`]). Open surfaces only.
    pub border_reach: f64,
    /// Vertex colours from the points' attributes (default `rgb`: the points' RGB when the input
    /// has it, else none).
    pub color: crate::mesh::ColorMode,
    /// Chord-error tolerance of the output mesh, which sets its triangle count (default
    /// `0.03` × the median point spacing; [`ChordTolerance::Off`] keeps every grid triangle).
    pub chord_error: ChordTolerance,
}

/// How far the output mesh may deviate from the polygonized surface: the marching-tetrahedra mesh
/// is simplified by edge collapses ([`crate::mesh::simplify`]) up to this deviation, keeping its
/// topology, so flat parts get few large triangles and curved parts as many as they need.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChordTolerance {
    /// No simplification: every triangle of the grid.
    Off,
    /// Largest deviation, as a fraction of the median point spacing (in (0, 2]).
    Spacing(f64),
}

/// The default chord error in point spacings. Measured at 0.05: armadillo 10k 178k → 63k
/// triangles, Chamfer to the truth 4.89e-4 → 4.94e-4; camel 10k 182k → 39k, 2.86e-4 → 2.93e-4;
/// at 0.1 the counts halve again but the Chamfer grows by 3–12%. 0.03 measured on clean dense
/// data: at 0.05 the clean bunny (37,706 points) lost a third of its accuracy
/// (Chamfer to `bunny00.off` 4.5e-5 unsimplified → 6.0e-5), at 0.03 4.7e-5 with 63k triangles
/// instead of 41k.
pub const DEFAULT_CHORD_SPACING: f64 = 0.03;

impl Default for ChordTolerance {
    fn default() -> Self {
        ChordTolerance::Spacing(DEFAULT_CHORD_SPACING)
    }
}

impl std::str::FromStr for ChordTolerance {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "off" => Ok(ChordTolerance::Off),
            "auto" => Ok(ChordTolerance::default()),
            _ => s.parse::<f64>().map(ChordTolerance::Spacing).map_err(|_| {
                format!(
                    "chord-error '{s}': use auto, off or a fraction of the point spacing, e.g. 0.03"
                )
            }),
        }
    }
}

impl std::fmt::Display for ChordTolerance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ChordTolerance::Off => f.write_str("off"),
            ChordTolerance::Spacing(x) => write!(f, "{x}"),
        }
    }
}

/// `chord-error`: `auto` (the default, [`DEFAULT_CHORD_SPACING`]), `off` or a fraction of the point
/// spacing in (0, 2] (a plain decimal number): below 1, from 1 to below 2, or 2. The spellings
/// [`chord_error_spelled`] accepts.
pub const CHORD_ERROR_PATTERN: &str =
    "^(auto|off|0*\\.[0-9]*[1-9][0-9]*|0*1(\\.[0-9]+)?|0*2(\\.0+)?)$";

/// Whether `value` matches [`CHORD_ERROR_PATTERN`] (written out: the API enforces exactly what its
/// document states).
pub fn chord_error_spelled(value: &str) -> bool {
    if value == "auto" || value == "off" {
        return true;
    }
    let (int, frac) = match value.split_once('.') {
        Some((i, f)) => (i, Some(f)),
        None => (value, None),
    };
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    if !digits(int) || frac.is_some_and(|f| f.is_empty() || !digits(f)) {
        return false;
    }
    match (int.trim_start_matches('0'), frac) {
        ("", Some(f)) => f.bytes().any(|b| b != b'0'),
        ("1", _) => true,
        ("2", f) => f.is_none_or(|f| f.bytes().all(|b| b == b'0')),
        _ => false,
    }
}

impl Default for ReconParams {
    fn default() -> Self {
        ReconParams {
            method: Method::Csrbf,
            kernel: Kernel::default(),
            support: Support::default(),
            carrier: CarrierParams::default(),
            index: IndexKind::default(),
            leaf_size: 16,
            ordering: OrderingKind::Bfs,
            solver: SolverKind::Auto,
            polynomial: Polynomial::None,
            resolution: None,
            clean: CleanParams::default(),
            max_memory_mib: 8192,
            smoothing: Smoothing::Auto,
            outliers: None,
            boundary: Boundary::Auto,
            levels: 1,
            blocks: crate::rbf::Blocks::Auto,
            min_component: 0.0,
            min_support: 0.01,
            max_handle_loop: DEFAULT_MAX_HANDLE_LOOP,
            border_reach: DEFAULT_BORDER_REACH,
            color: crate::mesh::ColorMode::Rgb,
            chord_error: ChordTolerance::default(),
        }
    }
}

/// How the smoothing λ on the matrix diagonal is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Smoothing {
    /// From the measured noise ([`crate::rbf::noise::estimate_noise`]): 0 on clean data.
    #[default]
    Auto,
    /// This λ (0 = interpolate).
    Lambda(f64),
}

impl Smoothing {
    /// The fixed λ (0 for `Auto`, which the pipeline resolves before assembly).
    pub fn lambda(self) -> f64 {
        match self {
            Smoothing::Auto => 0.0,
            Smoothing::Lambda(l) => l,
        }
    }
}

/// A parameter outside its valid range.
#[derive(Debug, thiserror::Error)]
#[error("invalid parameter {name} = {value}: {expected}")]
pub struct ParamError {
    /// Parameter name as on the command line (`support`, `neighbours`, ...).
    pub name: &'static str,
    /// The offending value.
    pub value: String,
    /// What is allowed.
    pub expected: std::borrow::Cow<'static, str>,
}

/// The allowed values of one numeric parameter: the single definition that
/// [`ReconParams::validate`] checks and the HTTP API's OpenAPI document publishes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Parameter name as on the command line and in the API.
    pub name: &'static str,
    /// Whole numbers only.
    pub integer: bool,
    /// Lower bound.
    pub min: f64,
    /// The lower bound itself is excluded.
    pub exclusive_min: bool,
    /// Upper bound (inclusive), if any.
    pub max: Option<f64>,
    /// What the value is, said before its bounds in an error (`a radius`, `an integer`).
    pub what: &'static str,
    /// Said after the bounds in an error (units, a hint); may be empty.
    pub note: &'static str,
}

impl Range {
    const fn int(name: &'static str, min: u64, max: u64) -> Range {
        Range {
            name,
            integer: true,
            min: min as f64,
            exclusive_min: false,
            max: Some(max as f64),
            what: "an integer",
            note: "",
        }
    }

    const fn num(name: &'static str, min: f64, exclusive_min: bool, max: Option<f64>) -> Range {
        Range {
            name,
            integer: false,
            min,
            exclusive_min,
            max,
            what: "a number",
            note: "",
        }
    }

    /// The same range, described as `what` … `note` in its error.
    const fn said(self, what: &'static str, note: &'static str) -> Range {
        Range { what, note, ..self }
    }

    /// The allowed values in words, from the bounds themselves: `an integer in 4..=2000`,
    /// `a radius in (0, 2] normalised units (…)`, `a number > 0 (e.g. 2.5)`.
    pub fn expected(&self) -> String {
        let open = if self.exclusive_min { "(" } else { "[" };
        let bounds = match self.max {
            Some(max) if self.integer => format!("in {}..={max}", self.min),
            Some(max) => format!("in {open}{}, {max}]", self.min),
            None if self.exclusive_min => format!("> {}", self.min),
            None => format!(">= {}", self.min),
        };
        format!("{} {bounds}{}", self.what, self.note)
    }

    /// `Ok` when `v` is inside the range, else the error naming this parameter with the
    /// value as `shown`.
    pub fn check(&self, v: f64, shown: impl ToString) -> Result<(), ParamError> {
        if self.contains(v) {
            return Ok(());
        }
        Err(ParamError {
            name: self.name,
            value: shown.to_string(),
            expected: self.expected().into(),
        })
    }

    /// True when `v` is finite and inside the range.
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && if self.exclusive_min {
                v > self.min
            } else {
                v >= self.min
            }
            && self.max.is_none_or(|m| v <= m)
    }
}

/// `support`: a radius in (0, 2] normalised units.
pub const SUPPORT: Range = Range::num("support", 0.0, true, Some(2.0))
    .said("a radius", " normalised units (the longest bbox edge is 1)");
/// `neighbours`: 4..=2000.
pub const NEIGHBOURS: Range = Range::int("neighbours", 4, 2000);
/// `resolution`: 8..=4096 (a server may allow less).
pub const RESOLUTION: Range = Range::int("resolution", 8, 4096);
/// `leaf-size`: 1..=4096.
pub const LEAF_SIZE: Range = Range::int("leaf-size", 1, 4096);
/// `merge-tolerance`: [0, 0.01] of the bbox diagonal.
pub const MERGE_TOLERANCE: Range = Range::num("merge-tolerance", 0.0, false, Some(1e-2))
    .said("a fraction of the bbox diagonal", "");
/// `max-memory-mib`: 16..=4194304 (a server caps it at its own budget).
pub const MAX_MEMORY_MIB: Range = Range::int("max-memory-mib", 16, 1 << 22).said("MiB", "");
/// `smoothing`: λ in [0, 10].
pub const SMOOTHING: Range = Range::num("smoothing", 0.0, false, Some(10.0));
/// `outlier-std-ratio`: positive.
pub const OUTLIER_STD_RATIO: Range =
    Range::num("outlier-std-ratio", 0.0, true, None).said("a number", " (e.g. 2.5)");
/// The outlier test's neighbour count (16 from the options): 2..=200.
pub const OUTLIER_NEIGHBOURS: Range = Range::int("outlier-neighbours", 2, 200);
/// `levels`: 1..=8.
pub const LEVELS: Range = Range::int("levels", 1, 8);
/// `min-component`: [0, 1].
pub const MIN_COMPONENT: Range = Range::num("min-component", 0.0, false, Some(1.0))
    .said("a fraction of the largest component", "");
/// `min-support`: [0, 0.5].
pub const MIN_SUPPORT: Range =
    Range::num("min-support", 0.0, false, Some(0.5)).said("a fraction of the data points", "");
/// `max-handle-loop`: [0, 4] support radii. Real handles can be that short (the elephant's trunk
/// and legs: 3.5 R on a 10k sample), and the search's cost grows steeply with the length (man 26k
/// `x y z`, idle: 0.9 s at 2 R, 8.3 s at 4 R, 93 s at 8 R).
pub const MAX_HANDLE_LOOP: Range = Range::num("max-handle-loop", 0.0, false, Some(4.0))
    .said("a loop length in support radii", " (0 keeps every handle)");
/// Default `max-handle-loop`, support radii: the spurious handles of 10k-point statue samples
/// measured 0.1–2.0 R; the real ones measured 3.5 R and more (the elephant's).
pub const DEFAULT_MAX_HANDLE_LOOP: f64 = 2.0;
/// `border-reach`: [0.25, 1] support radii. Below a quarter radius the border would be peeled into
/// the band between samples, where the surface is an interpolation anyway.
pub const BORDER_REACH: Range = Range::num("border-reach", 0.25, false, Some(1.0)).said(
    "a distance in support radii",
    " (1 keeps the trim's border)",
);
/// Default `border-reach`, support radii: on the outdoor scene b9 the mesh→scan mean distance of
/// the surface within 0.25 R of a point is 4.7e-4 of the diagonal, between 0.25 R and R 2–5e-3.
pub const DEFAULT_BORDER_REACH: f64 = 0.5;
/// `lods`: 0..=8 levels of detail beside a GLB.
pub const LODS: Range = Range::int("lods", 0, 8);

/// Every numeric parameter's range.
pub const RANGES: [Range; 14] = [
    SUPPORT,
    NEIGHBOURS,
    RESOLUTION,
    LEAF_SIZE,
    MERGE_TOLERANCE,
    MAX_MEMORY_MIB,
    SMOOTHING,
    OUTLIER_STD_RATIO,
    LEVELS,
    MIN_COMPONENT,
    MIN_SUPPORT,
    MAX_HANDLE_LOOP,
    BORDER_REACH,
    LODS,
];

/// The exact spellings each choice parameter accepts (the HTTP API accepts only these; the
/// command line also takes a few aliases). `blocks` is not here: it also takes a number.
pub fn choices() -> Vec<(&'static str, Vec<&'static str>)> {
    vec![
        (
            "method",
            [Method::Csrbf, Method::Variational, Method::Mls]
                .map(Method::name)
                .to_vec(),
        ),
        ("kernel", Kernel::ALL.map(Kernel::name).to_vec()),
        (
            "carrier",
            [
                CarrierKind::Auto,
                CarrierKind::Sphere,
                CarrierKind::Ellipsoid,
                CarrierKind::Local,
            ]
            .map(CarrierKind::name)
            .to_vec(),
        ),
        ("local-fit", LocalFit::ALL.map(LocalFit::name).to_vec()),
        ("ordering", ["none", "bfs", "rcm"].to_vec()),
        ("solver", SolverKind::ALL.map(SolverKind::name).to_vec()),
        ("polynomial", ["none", "linear"].to_vec()),
        ("index", ["octree", "kdtree"].to_vec()),
        ("boundary", ["auto", "trim", "closed"].to_vec()),
        ("color", ["rgb", "intensity", "none"].to_vec()),
        (
            "glb-compression",
            crate::io::GlbCompression::ALL
                .map(crate::io::GlbCompression::name)
                .to_vec(),
        ),
    ]
}

/// `blocks`: `auto`, `none` or a maximum number of points per block (1000 or more).
pub const BLOCKS_PATTERN: &str = "^(auto|none|[1-9][0-9]{3,8})$";

impl ReconParams {
    /// These parameters with what the measured `noise` chooses resolved: the smoothing λ (`auto`
    /// takes the estimate's) and the local carrier's fit (`auto`: wide quadrics on noisy data, else
    /// quadrics).
    pub fn resolved_for(&self, noise: &crate::rbf::NoiseEstimate) -> ReconParams {
        ReconParams {
            smoothing: Smoothing::Lambda(match self.smoothing {
                Smoothing::Auto => noise.lambda,
                Smoothing::Lambda(l) => l,
            }),
            carrier: CarrierParams {
                fit: self.carrier.fit.resolve(noise.noisy),
                ..self.carrier
            },
            ..self.clone()
        }
    }

    /// Check ranges; the command line and the HTTP API call this before any work.
    pub fn validate(&self) -> Result<(), ParamError> {
        match self.support {
            Support::Radius(r) => SUPPORT.check(r, r)?,
            Support::Neighbours(k) => NEIGHBOURS.check(k as f64, k)?,
        }
        if let Some(r) = self.resolution {
            RESOLUTION.check(r as f64, r)?;
        }
        LEAF_SIZE.check(self.leaf_size as f64, self.leaf_size)?;
        let tol = self.clean.merge_tolerance;
        MERGE_TOLERANCE.check(tol, tol)?;
        if let Smoothing::Lambda(l) = self.smoothing {
            SMOOTHING.check(l, l)?;
        }
        if let Some(o) = self.outliers {
            OUTLIER_STD_RATIO.check(o.std_ratio, o.std_ratio)?;
            OUTLIER_NEIGHBOURS.check(o.neighbours as f64, o.neighbours)?;
        }
        MIN_COMPONENT.check(self.min_component, self.min_component)?;
        MIN_SUPPORT.check(self.min_support, self.min_support)?;
        MAX_HANDLE_LOOP.check(self.max_handle_loop, self.max_handle_loop)?;
        BORDER_REACH.check(self.border_reach, self.border_reach)?;
        if let ChordTolerance::Spacing(x) = self.chord_error
            && !(x.is_finite() && x > 0.0 && x <= 2.0)
        {
            return Err(ParamError {
                name: "chord-error",
                value: x.to_string(),
                expected: "off or a fraction of the point spacing in (0, 2]".into(),
            });
        }
        LEVELS.check(self.levels as f64, self.levels)?;
        MAX_MEMORY_MIB.check(self.max_memory_mib as f64, self.max_memory_mib)?;
        Ok(())
    }
}

/// The user-facing parameters, every one optional (`None` = the library default): one definition
/// shared by the command line (flattened into `rbfsurf reconstruct`) and the HTTP API (query string
/// or multipart fields, same kebab-case names). Converted and validated by
/// `ReconParams::try_from(&ReconOptions)`.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(feature = "server", derive(utoipa::IntoParams))]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
#[cfg_attr(feature = "server", into_params(parameter_in = Query))]
pub struct ReconOptions {
    /// Method: csrbf (default), variational (Turk–O'Brien r³, dense; refused above 12,000 unknowns ≈ 6,000 points, practical up to ~2–3k), mls (Shen).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub method: Option<Method>,
    /// Kernel: wendland-c0 (seed), wendland-c2 (default), wendland-c4.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub kernel: Option<Kernel>,
    /// Support radius R in normalised units (the longest bbox edge is 1).
    #[cfg_attr(
        feature = "cli",
        arg(long, conflicts_with = "neighbours", allow_negative_numbers = true)
    )]
    #[serde(default)]
    pub support: Option<f64>,
    /// Choose R to give about K neighbours per point (default 30).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub neighbours: Option<usize>,
    /// Carrier solid: auto (default: local with normals, else ellipsoid), sphere, ellipsoid, local.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub carrier: Option<crate::rbf::CarrierKind>,
    /// Each point's term of the local carrier: auto (default: quadric on clean data, wide-quadric when noise is measured), plane (tangent planes), quadric (local quadrics fitted to the neighbours within R whose normals agree), wide-quadric (the same fitted within 2R: averages noise).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub local_fit: Option<crate::rbf::LocalFit>,
    /// Matrix ordering: none, bfs (default, seed Algorithm III), rcm.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub ordering: Option<OrderingKind>,
    /// Solver: auto (default: conjugate gradients first when smoothing λ ≥ 0.1, falling back to sparse after 250 iterations; otherwise sparse when its factor fits --max-memory-mib, else cg), sparse (faer supernodal Cholesky + AMD), envelope (own Jennings profile Cholesky), ldl (sprs-ldl), cg (Jacobi-preconditioned conjugate gradients, no factor).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub solver: Option<SolverKind>,
    /// Polynomial part: none (default) or linear (doubly bordered system).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub polynomial: Option<Polynomial>,
    /// Marching grid cells along the longest axis (default: from the point spacing, 64..200).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub resolution: Option<usize>,
    /// Spatial index: octree (default) or kdtree.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub index: Option<IndexKind>,
    /// Octree leaf size K (default 16).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub leaf_size: Option<usize>,
    /// Merge points closer than this fraction of the bbox diagonal (default 1e-6).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub merge_tolerance: Option<f64>,
    /// Memory budget in MiB (default 8192; alias --max-memory): inputs whose reconstruction would not fit are refused before reading, systems whose matrix or factor would not fit before allocating.
    #[cfg_attr(feature = "cli", arg(long, visible_alias = "max-memory"))]
    #[serde(default, alias = "max-memory")]
    pub max_memory_mib: Option<u64>,
    /// Smoothing λ on the matrix diagonal: 0 interpolates, 1e-3..1 approximates noisy scans; default: chosen from the measured noise (0 on clean data; report params.noise).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub smoothing: Option<f64>,
    /// Remove statistical outliers: points whose mean distance to 16 neighbours exceeds the median by this many robust standard deviations (1.4826 · MAD) (e.g. 3; default off).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub outlier_std_ratio: Option<f64>,
    /// Unsupported surface: auto (default: with the local carrier, open when more than 2% of a coarse pass's surface is farther than R from the data, the data leave a cone wider than 25° empty around their middle and their oriented points enclose no volume — a single-view scan or open scene — else closed, e.g. data all around an object with occlusion holes), trim (polygonize only the data band; manifold border), closed.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub boundary: Option<Boundary>,
    /// CSRBF levels, coarse to fine, each halving the support radius: 1 (default, the seed's single level) to 8; more levels adapt to uneven density at ~2.5× the evaluation cost (4 levels measured on the bunny).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub levels: Option<usize>,
    /// Partition-of-unity blocks: auto (default: one system up to 250,000 points, blocks of at most 250,000 above), none (one global system), or the maximum points per block (≥ 1000).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub blocks: Option<crate::rbf::Blocks>,
    /// Drop connected components with fewer triangles than this fraction of the largest (0 = keep all, the default; 0.01 removes floaters from noise and outliers).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub min_component: Option<f64>,
    /// Drop floaters: components carried by fewer than this fraction of the data points (default 0.01; 0 keeps all; two separate objects both stay).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub min_support: Option<f64>,
    /// Cut small handles: thin bridges and pinholes whose shortest loop around is at most this many support radii long (default 2; 0 keeps every handle; closed surfaces only). The report says what was cut (polygonize.handles_removed, handle_loop_max).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub max_handle_loop: Option<f64>,
    /// How far an open surface's border may reach beyond its data, in support radii (default 0.5; 1 keeps the trim's border at one support radius): the border is peeled back to it wherever that keeps the pieces, holes and handles. The report counts the peeled triangles (polygonize.peeled_triangles).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default)]
    pub border_reach: Option<f64>,
    /// Vertex colours: rgb (default: the points' RGB, 8 or 16 bit, when the input has it — LAS/LAZ, E57 — else none), intensity (the points' intensity as grey), none. A smooth distance-weighted blend of the points within the support radius; written as COLOR_0 in GLB and red green blue in PLY.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub color: Option<crate::mesh::ColorMode>,
    /// Chord error of the output mesh, as a fraction of the median point spacing (auto = the default 0.03): the grid's triangles are merged by edge collapses while the mesh stays this close to the polygonized surface and keeps its topology, so flat parts get few large triangles; off keeps every grid triangle. The report gives the tolerance and the chord error measured on the result (polygonize.chord_error_*).
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub chord_error: Option<ChordTolerance>,
    /// GLB storage: meshopt (default: KHR_mesh_quantization + EXT_meshopt_compression, 16-bit positions dequantized by the node transform, about 4–5 bytes per triangle; read by three.js, Babylon.js, gltfpack and rbfsurf) or none (plain float glTF, 24 bytes per triangle, for tools without a meshopt decoder). An output option: the mesh itself does not change.
    #[cfg_attr(feature = "cli", arg(long))]
    #[serde(default, with = "from_str_opt")]
    #[cfg_attr(feature = "server", param(value_type = Option<String>))]
    pub glb_compression: Option<crate::io::GlbCompression>,
    /// Also write N simplified levels of detail beside a .glb mesh (0..=8, default 0): OUT.lod1.glb … OUT.lodN.glb (the service: GET …/lods/{level}), each about a quarter of the previous level's triangles, simplification error at most k·0.2 % of the bbox diagonal (the measured error in each file's asset.extras.lod); the main file keeps the full mesh.
    #[cfg_attr(feature = "cli", arg(long, value_name = "N"))]
    #[serde(default)]
    pub lods: Option<usize>,
}

impl ReconOptions {
    /// The GLB writer options these options ask for.
    pub fn glb(&self) -> crate::io::GlbOptions {
        crate::io::GlbOptions {
            compression: self.glb_compression.unwrap_or_default(),
            lods: self.lods.unwrap_or(0),
        }
    }
}

impl TryFrom<&ReconOptions> for ReconParams {
    type Error = ParamError;
    fn try_from(a: &ReconOptions) -> Result<Self, Self::Error> {
        let d = ReconParams::default();
        let support = match (a.support, a.neighbours) {
            (Some(_), Some(k)) => {
                return Err(ParamError {
                    name: "neighbours",
                    value: k.to_string(),
                    expected: "either support (a radius) or neighbours (a count), not both".into(),
                });
            }
            (Some(r), None) => Support::Radius(r),
            (None, Some(k)) => Support::Neighbours(k),
            (None, None) => d.support,
        };
        if let Some(n) = a.lods {
            LODS.check(n as f64, n)?;
        }
        let method = a.method.unwrap_or(d.method);
        if method != Method::Csrbf
            && let Some((name, value)) = a
                .support
                .map(|r| ("support", r.to_string()))
                .or_else(|| a.neighbours.map(|k| ("neighbours", k.to_string())))
        {
            return Err(ParamError {
                name,
                value,
                expected: "only with method csrbf (variational and mls choose their own scale)"
                    .into(),
            });
        }
        let p = ReconParams {
            method,
            kernel: a.kernel.unwrap_or(d.kernel),
            support,
            carrier: CarrierParams {
                kind: a.carrier.unwrap_or(d.carrier.kind),
                fit: a.local_fit.unwrap_or(d.carrier.fit),
            },
            index: a.index.unwrap_or(d.index),
            leaf_size: a.leaf_size.unwrap_or(d.leaf_size),
            ordering: a.ordering.unwrap_or(d.ordering),
            solver: a.solver.unwrap_or(d.solver),
            polynomial: a.polynomial.unwrap_or(d.polynomial),
            resolution: a.resolution.or(d.resolution),
            clean: CleanParams {
                merge_tolerance: a.merge_tolerance.unwrap_or(d.clean.merge_tolerance),
            },
            max_memory_mib: a.max_memory_mib.unwrap_or(d.max_memory_mib),
            smoothing: a.smoothing.map_or(d.smoothing, Smoothing::Lambda),
            outliers: a
                .outlier_std_ratio
                .map(|std_ratio| crate::clean::outliers::OutlierParams {
                    std_ratio,
                    ..Default::default()
                }),
            boundary: a.boundary.unwrap_or(d.boundary),
            levels: a.levels.unwrap_or(d.levels),
            blocks: a.blocks.unwrap_or(d.blocks),
            min_component: a.min_component.unwrap_or(d.min_component),
            min_support: a.min_support.unwrap_or(d.min_support),
            max_handle_loop: a.max_handle_loop.unwrap_or(d.max_handle_loop),
            border_reach: a.border_reach.unwrap_or(d.border_reach),
            color: a.color.unwrap_or(d.color),
            chord_error: a.chord_error.unwrap_or(d.chord_error),
        };
        p.validate()?;
        Ok(p)
    }
}

/// Serde adapter: an optional value written as its `Display` and read with `FromStr`
/// (so the HTTP API accepts exactly the command line's spellings).
mod from_str_opt {
    use serde::{Deserialize, Deserializer, Serializer};
    use std::fmt::Display;
    use std::str::FromStr;

    pub fn serialize<T: Display, S: Serializer>(v: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(v) => s.collect_str(v),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, T, D>(d: D) -> Result<Option<T>, D::Error>
    where
        T: FromStr,
        T::Err: Display,
        D: Deserializer<'de>,
    {
        Option::<String>::deserialize(d)?
            .map(|s| s.parse::<T>().map_err(serde::de::Error::custom))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_choice_parses_and_blocks_follow_the_pattern() {
        for (name, values) in choices() {
            for v in values {
                let o: Result<ReconOptions, _> =
                    serde_json::from_value(serde_json::json!({ name: v }));
                assert!(o.is_ok(), "{name}={v}");
            }
        }
        for (v, ok) in [
            ("auto", true),
            ("none", true),
            ("1000", true),
            ("999", false),
        ] {
            assert_eq!(v.parse::<crate::rbf::Blocks>().is_ok(), ok, "{v}");
        }
        assert!(SUPPORT.contains(2.0) && !SUPPORT.contains(0.0) && !SUPPORT.contains(f64::NAN));
    }

    #[test]
    fn options_map_to_params_with_defaults_and_validation() {
        let p = ReconParams::try_from(&ReconOptions::default()).unwrap();
        assert_eq!(p, ReconParams::default());
        let o: ReconOptions = serde_json::from_str(
            r#"{"kernel":"wendland-c4","support":0.1,"solver":"envelope","leaf-size":8}"#,
        )
        .unwrap();
        let p = ReconParams::try_from(&o).unwrap();
        assert_eq!(p.kernel, Kernel::WendlandC4);
        assert_eq!(p.support, Support::Radius(0.1));
        assert_eq!(p.solver, SolverKind::Envelope);
        assert_eq!(p.leaf_size, 8);
        assert!(serde_json::from_str::<ReconOptions>(r#"{"kernel":"gauss"}"#).is_err());
        assert!(serde_json::from_str::<ReconOptions>(r#"{"bogus":1}"#).is_err());
        let bad = ReconOptions {
            resolution: Some(2),
            ..Default::default()
        };
        assert_eq!(ReconParams::try_from(&bad).unwrap_err().name, "resolution");
        let both = ReconOptions {
            support: Some(0.1),
            neighbours: Some(20),
            ..Default::default()
        };
        assert_eq!(ReconParams::try_from(&both).unwrap_err().name, "neighbours");
        let global = ReconOptions {
            method: Some(Method::Mls),
            support: Some(0.1),
            ..Default::default()
        };
        assert_eq!(ReconParams::try_from(&global).unwrap_err().name, "support");
        let round: ReconOptions =
            serde_json::from_str(&serde_json::to_string(&o).unwrap()).unwrap();
        assert_eq!(round, o);
    }

    #[test]
    fn range_errors_say_the_bounds_of_the_range_itself() {
        assert_eq!(NEIGHBOURS.expected(), "an integer in 4..=2000");
        assert_eq!(MAX_MEMORY_MIB.expected(), "MiB in 16..=4194304");
        assert_eq!(
            SUPPORT.expected(),
            "a radius in (0, 2] normalised units (the longest bbox edge is 1)"
        );
        assert_eq!(
            MERGE_TOLERANCE.expected(),
            "a fraction of the bbox diagonal in [0, 0.01]"
        );
        assert_eq!(OUTLIER_STD_RATIO.expected(), "a number > 0 (e.g. 2.5)");
        let p = ReconParams {
            resolution: Some(4097),
            ..Default::default()
        };
        let e = p.validate().unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid parameter resolution = 4097: an integer in 8..=4096"
        );
        let p = ReconParams {
            smoothing: Smoothing::Lambda(f64::INFINITY),
            ..Default::default()
        };
        assert_eq!(p.validate().unwrap_err().expected, "a number in [0, 10]");
    }
}

#[cfg(test)]
mod chord_error_spelling_tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_pattern_s_spellings_are_the_numbers_in_range() {
        for ok in [
            "auto", "off", "0.03", ".5", "00.1", "1", "1.999", "01.5", "2", "2.000",
        ] {
            assert!(chord_error_spelled(ok), "{ok}");
        }
        for bad in [
            "",
            ".",
            "0",
            "0.0",
            "00",
            "2.01",
            "3",
            "10",
            "1.",
            ".0",
            "-1",
            "1e-2",
            "0x1",
            " 1",
            "5108809357169005659.1513271",
            "Auto",
        ] {
            assert!(!chord_error_spelled(bad), "{bad}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]
        /// A plain decimal is spelled right exactly when it is a tolerance the parameters accept.
        #[test]
        fn spelled_decimals_are_the_valid_tolerances(s in "[0-9]{0,3}(\\.[0-9]{0,4})?") {
            let decimal = !s.is_empty() && !s.ends_with('.') && s != ".";
            let valid = decimal
                && s.parse::<ChordTolerance>().is_ok_and(|c| ReconParams {
                    chord_error: c,
                    ..Default::default()
                }
                .validate()
                .is_ok());
            prop_assert_eq!(chord_error_spelled(&s), valid, "{}", s);
        }
    }
}
