//! Composition and morph jobs: the request bodies, their validation (operands are ids of finished
//! CSRBF jobs or primitives; never server paths) and the worker side that meshes them into the
//! job's `mesh.glb` and `report.json`, like a reconstruction.

use super::error::ErrorBody;
use super::store::Store;
use crate::frep::expr::{Expr, Loader, build};
use crate::frep::{Align, CsgParams, FrepError, MorphParams, format, parse};
use crate::io::{MeshFormat, encode_animated_glb, write_atomic, write_mesh};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use uuid::Uuid;

/// Largest resolution a composition or morph job may ask for.
pub const MAX_RESOLUTION: usize = 400;
/// Most frames a morph job may ask for.
pub const MAX_FRAMES: usize = 64;

/// `POST /v1/compositions`: an expression over finished jobs' fields and primitives.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"expression": "difference(sphere(0, 0, 0, 0.4), box(0, 0, 0, 1, 1, 1))", "resolution": 24}))]
pub struct CompositionRequest {
    /// The expression (docs/volume-modelling.md); field operands are job ids, e.g.
    /// `difference(0b6f…-…, sphere(0, 0, 0, 0.3))`. One that does not parse is answered 422.
    pub expression: String,
    /// Grid cells along the longest edge (default 160, 8..=400).
    #[schema(minimum = 8, maximum = 400)]
    #[serde(default, deserialize_with = "integral")]
    pub resolution: Option<usize>,
}

/// An optional count from a JSON integer or from a number without a fractional part (`24.0`),
/// as JSON Schema's `integer` allows.
fn integral<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<usize>, D::Error> {
    let Some(n) = Option::<serde_json::Number>::deserialize(d)? else {
        return Ok(None);
    };
    let whole = n.as_u64().or_else(|| {
        n.as_f64()
            .filter(|f| f.fract() == 0.0 && *f >= 0.0 && *f <= u64::MAX as f64)
            .map(|f| f as u64)
    });
    whole
        .and_then(|v| usize::try_from(v).ok())
        .map(Some)
        .ok_or_else(|| serde::de::Error::custom(format!("{n} is not a count (a whole number ≥ 0)")))
}

/// `POST /v1/morphs`: a metamorphosis between two expressions (job ids or primitives).
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"a": "sphere(0, 0, 0, 0.4)", "b": "box(-0.3, -0.3, -0.3, 0.3, 0.3, 0.3)", "frames": 3, "resolution": 16}))]
pub struct MorphRequest {
    /// The start (an expression; a job id alone is the simplest). One that does not parse is
    /// answered 422, as for `b` and `obstacle`.
    pub a: String,
    /// The end, aligned to the start first.
    pub b: String,
    /// Frames including both ends (default 8, 2..=64).
    #[schema(minimum = 2, maximum = 64)]
    #[serde(default, deserialize_with = "integral")]
    pub frames: Option<usize>,
    /// An expression no frame may enter.
    pub obstacle: Option<String>,
    /// `bbox` (default), `pca` or `none`.
    #[schema(pattern = "^(bbox|pca|none)$")]
    pub align: Option<String>,
    /// Grid cells along the longest edge (default 128, 8..=400).
    #[schema(minimum = 8, maximum = 400)]
    #[serde(default, deserialize_with = "integral")]
    pub resolution: Option<usize>,
}

/// Why a volume request cannot be run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VolumeRequestError {
    /// A number outside its range or an unknown `align` (the request's schema states them).
    #[error("{0}")]
    Range(String),
    /// An expression that does not parse, calls an unknown operation, or names an operand that
    /// is not a job id.
    #[error("{0}")]
    Expression(String),
}

impl VolumeRequestError {
    /// The error body's code: `bad_parameter` or `invalid_expression`.
    pub fn code(&self) -> &'static str {
        match self {
            VolumeRequestError::Range(_) => "bad_parameter",
            VolumeRequestError::Expression(_) => "invalid_expression",
        }
    }
}

/// The stored request of a volume job (`request.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum VolumeRequest {
    /// A composition.
    Composition(CompositionRequest),
    /// A morph.
    Morph(MorphRequest),
}

/// `InputInfo::format` of composition jobs.
pub const COMPOSITION: &str = "composition";
/// `InputInfo::format` of morph jobs.
pub const MORPH: &str = "morph";
/// Stored request file name.
pub const REQUEST_FILE: &str = "request.json";

impl VolumeRequest {
    /// The expressions to check and load.
    fn expressions(&self) -> Vec<&str> {
        match self {
            VolumeRequest::Composition(c) => vec![c.expression.as_str()],
            VolumeRequest::Morph(m) => [Some(&m.a), Some(&m.b), m.obstacle.as_ref()]
                .into_iter()
                .flatten()
                .map(String::as_str)
                .collect(),
        }
    }

    /// Check ranges and parse every expression; returns the job ids the operands name.
    pub fn validate(&self) -> Result<Vec<Uuid>, VolumeRequestError> {
        use VolumeRequestError::{Expression, Range};
        let (res, frames) = match self {
            VolumeRequest::Composition(c) => (c.resolution, None),
            VolumeRequest::Morph(m) => (m.resolution, m.frames),
        };
        if let Some(r) = res
            && !(8..=MAX_RESOLUTION).contains(&r)
        {
            return Err(Range(format!(
                "resolution {r} is outside 8..={MAX_RESOLUTION}"
            )));
        }
        if let Some(f) = frames
            && !(2..=MAX_FRAMES).contains(&f)
        {
            return Err(Range(format!("frames {f} is outside 2..={MAX_FRAMES}")));
        }
        if let VolumeRequest::Morph(m) = self {
            align(m).map_err(Range)?;
        }
        let mut ids = Vec::new();
        for e in self.expressions() {
            let parsed = parse(e).map_err(|e| Expression(e.to_string()))?;
            for p in parsed.paths() {
                let id = Uuid::parse_str(p).map_err(|_| {
                    Expression(format!("operand '{p}' is not a job id (operands are finished job ids or primitives)"))
                })?;
                ids.push(id);
            }
            check_calls(&parsed).map_err(Expression)?;
        }
        Ok(ids)
    }
}

/// Unknown operations and arities are found without loading anything: build with placeholder
/// operands (unit spheres).
fn check_calls(e: &Expr) -> Result<(), String> {
    fn placeholder(e: &Expr) -> Expr {
        match e {
            Expr::Path(_, c) => Expr::Call(
                "sphere".into(),
                [0.0, 0.0, 0.0, 1.0].map(|v| Expr::Num(v, *c)).to_vec(),
                *c,
            ),
            Expr::Num(..) => e.clone(),
            Expr::Call(n, args, c) => {
                Expr::Call(n.clone(), args.iter().map(placeholder).collect(), *c)
            }
        }
    }
    build(&placeholder(e), &mut Loader::preloaded_only())
        .map(|_| ())
        .map_err(|e| e.to_string())
}

fn align(m: &MorphRequest) -> Result<Align, String> {
    match m.align.as_deref().unwrap_or("bbox") {
        "bbox" => Ok(Align::BoundingBox),
        "pca" => Ok(Align::Pca),
        "none" => Ok(Align::None),
        other => Err(format!("unknown align '{other}' (use bbox, pca or none)")),
    }
}

fn failed(e: FrepError) -> ErrorBody {
    ErrorBody {
        code: e.kind().code().into(),
        message: e.to_string(),
    }
}

/// Run the volume job `id` (its request is stored): load the operands' fields, mesh, write
/// `mesh.glb` and `report.json`. Returns the triangle count.
pub fn run_volume_job(
    store: &Store,
    id: Uuid,
    progress: &dyn Progress,
) -> Result<usize, ErrorBody> {
    let bytes = std::fs::read(store.file(id, REQUEST_FILE))
        .map_err(|e| internal(format!("stored request unreadable: {e}")))?;
    let req = VolumeRequest::decode(&bytes)?;
    let mut load = |op: Uuid| format::read(&store.file(op, "fitted.field")).ok();
    let mesh = store.file(id, "mesh.glb");
    let report = store.file(id, "report.json");
    run_volume(&req, &mut load, &mesh, &report, progress)
}

fn internal(message: String) -> ErrorBody {
    ErrorBody {
        code: "internal".into(),
        message,
    }
}

impl VolumeRequest {
    /// The stored request (`request.json`).
    pub fn decode(bytes: &[u8]) -> Result<VolumeRequest, ErrorBody> {
        serde_json::from_slice(bytes).map_err(|e| internal(format!("stored request invalid: {e}")))
    }
}

/// Mesh `req` into `mesh_path` (GLB; animated for a morph) and `report_path` (JSON); `load`
/// gives the saved field of an operand job (`None`: gone, or no field). Returns the triangle
/// count (all frames of a morph). Used by the embedded service and by NATS workers.
pub fn run_volume(
    req: &VolumeRequest,
    load: &mut dyn FnMut(Uuid) -> Option<crate::frep::FieldModel>,
    mesh_path: &std::path::Path,
    report_path: &std::path::Path,
    progress: &dyn Progress,
) -> Result<usize, ErrorBody> {
    let ids = req.validate().map_err(|e| ErrorBody {
        code: e.code().into(),
        message: e.to_string(),
    })?;
    let mut loader = Loader::preloaded_only();
    for op in ids {
        let model = load(op).ok_or_else(|| ErrorBody {
            code: "bad_parameter".into(),
            message: format!("operand {op}: the job is gone or has no field"),
        })?;
        loader.insert(&op.hyphenated().to_string(), std::sync::Arc::new(model));
    }
    let solid = |e: &str, l: &mut Loader| parse(e).and_then(|x| build(&x, l)).map_err(failed);
    let (triangles, report) = match req {
        VolumeRequest::Composition(c) => {
            let s = solid(&c.expression, &mut loader)?;
            let params = CsgParams {
                resolution: c.resolution.unwrap_or(CsgParams::default().resolution),
                ..Default::default()
            };
            let (mesh, report) =
                crate::frep::mesh_solid(&s, &c.expression, &params, progress).map_err(failed)?;
            write_mesh(mesh_path, &mesh, MeshFormat::Glb(Default::default()))
                .map_err(|e| internal(e.to_string()))?;
            (mesh.triangles.len(), serde_json::to_vec_pretty(&report))
        }
        VolumeRequest::Morph(m) => {
            let (a, b) = (solid(&m.a, &mut loader)?, solid(&m.b, &mut loader)?);
            let obstacle = m
                .obstacle
                .as_deref()
                .map(|o| solid(o, &mut loader))
                .transpose()?;
            let params = MorphParams {
                frames: m.frames.unwrap_or(8),
                mesh: CsgParams {
                    resolution: m.resolution.unwrap_or(128),
                    ..Default::default()
                },
                align: align(m).map_err(|message| ErrorBody {
                    code: "bad_parameter".into(),
                    message,
                })?,
            };
            let mut frames = Vec::new();
            let report = crate::frep::morph(a, b, obstacle, &params, progress, |_, mesh| {
                frames.push(mesh);
                Ok(())
            })
            .map_err(failed)?;
            let glb = encode_animated_glb(&frames, 0.25).map_err(|e| internal(e.to_string()))?;
            write_atomic(mesh_path, &glb).map_err(|e| internal(e.to_string()))?;
            let n = frames.iter().map(|f| f.triangles.len()).sum();
            (n, serde_json::to_vec_pretty(&report))
        }
    };
    let report = report.map_err(|e| internal(e.to_string()))?;
    if let Err(e) = write_atomic(report_path, &report) {
        let _ = std::fs::remove_file(mesh_path);
        return Err(internal(e.to_string()));
    }
    Ok(triangles)
}
