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
pub struct CompositionRequest {
    /// The expression (docs/volume-modelling.md); field operands are job ids, e.g.
    /// `difference(0b6f…-…, sphere(0, 0, 0, 0.3))`.
    pub expression: String,
    /// Grid cells along the longest edge (default 160, at most 400).
    pub resolution: Option<usize>,
}

/// `POST /v1/morphs`: a metamorphosis between two expressions (job ids or primitives).
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MorphRequest {
    /// The start (an expression; a job id alone is the simplest).
    pub a: String,
    /// The end, aligned to the start first.
    pub b: String,
    /// Frames including both ends (default 8, 2..=64).
    pub frames: Option<usize>,
    /// An expression no frame may enter.
    pub obstacle: Option<String>,
    /// `bbox` (default), `pca` or `none`.
    pub align: Option<String>,
    /// Grid cells along the longest edge (default 128, at most 400).
    pub resolution: Option<usize>,
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
    pub fn validate(&self) -> Result<Vec<Uuid>, String> {
        let (res, frames) = match self {
            VolumeRequest::Composition(c) => (c.resolution, None),
            VolumeRequest::Morph(m) => (m.resolution, m.frames),
        };
        if let Some(r) = res
            && !(8..=MAX_RESOLUTION).contains(&r)
        {
            return Err(format!("resolution {r} is outside 8..={MAX_RESOLUTION}"));
        }
        if let Some(f) = frames
            && !(2..=MAX_FRAMES).contains(&f)
        {
            return Err(format!("frames {f} is outside 2..={MAX_FRAMES}"));
        }
        if let VolumeRequest::Morph(m) = self {
            align(m)?;
        }
        let mut ids = Vec::new();
        for e in self.expressions() {
            let parsed = parse(e).map_err(|e| e.to_string())?;
            for p in parsed.paths() {
                let id = Uuid::parse_str(p).map_err(|_| {
                    format!("operand '{p}' is not a job id (operands are finished job ids or primitives)")
                })?;
                ids.push(id);
            }
            check_calls(&parsed)?;
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
    let ids = req.validate().map_err(|m| ErrorBody {
        code: "bad_parameter".into(),
        message: m,
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
