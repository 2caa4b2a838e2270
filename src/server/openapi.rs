//! The OpenAPI document, generated from the handlers' `#[utoipa::path]` annotations through
//! `utoipa_axum` (so the documented paths are the routed ones). `rbfsurf openapi` prints it;
//! proto/openapi.json holds a copy that a test compares with this output.

use super::AppState;
use super::routes::{meta, reconstructions as rec};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

#[derive(OpenApi)]
#[openapi(
    info(title = "rbfsurf", description = "Watertight meshes from point clouds with compactly supported RBFs: upload a point file, follow the job, download the mesh and its report."),
    modifiers(&BearerAuth),
    components(schemas(crate::job::ErrorBody, crate::job::JobStatus, crate::job::InputInfo, crate::job::InputAttributes, crate::job::JobView))
)]
struct ApiDoc;

struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, api: &mut utoipa::openapi::OpenApi) {
        let components = api.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// The routed API with its documentation (handlers only; layers are added by `router`).
pub fn api_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(rec::create_job, rec::list_jobs))
        .routes(routes!(rec::get_job, rec::delete_job))
        .routes(routes!(rec::job_events))
        .routes(routes!(rec::mesh_glb))
        .routes(routes!(rec::mesh_lod))
        .routes(routes!(rec::mesh_ply))
        .routes(routes!(rec::mesh_obj))
        .routes(routes!(rec::job_report))
        .routes(routes!(rec::job_field))
        .routes(routes!(super::routes::volume::create_composition))
        .routes(routes!(super::routes::volume::create_morph))
        .routes(routes!(meta::health))
        .routes(routes!(meta::openapi_json))
        .routes(routes!(meta::index))
        .routes(routes!(meta::viewer_js))
        .routes(routes!(meta::meshopt_decoder_js))
        .routes(routes!(meta::meshopt_license))
}

/// The OpenAPI document: the handlers' annotations plus the parameter constraints
/// ([`contract`]).
pub fn openapi() -> utoipa::openapi::OpenApi {
    serde_json::from_value(document()).unwrap_or_else(|_| api_router().split_for_parts().1)
}

fn document() -> serde_json::Value {
    let mut api = api_router().split_for_parts().1;
    api.info.version = env!("CARGO_PKG_VERSION").to_string();
    let mut doc = serde_json::to_value(&api).unwrap_or_default();
    contract(&mut doc);
    doc
}

/// The OpenAPI document as pretty JSON with a trailing newline (the proto/openapi.json format).
pub fn openapi_json() -> String {
    let mut s = serde_json::to_string_pretty(&document())
        .unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"));
    s.push('\n');
    s
}

/// The JSON schema of query parameter `name`, from the one parameter definition
/// ([`crate::params::RANGES`], [`crate::params::choices`]) that the server enforces.
pub fn parameter_schema(name: &str) -> Option<serde_json::Value> {
    use serde_json::json;
    if name == "wait" {
        return Some(json!({"type": "number", "minimum": 0}));
    }
    if name == "blocks" {
        return Some(json!({"type": "string", "pattern": crate::params::BLOCKS_PATTERN}));
    }
    if name == "chord-error" {
        return Some(json!({"type": "string", "pattern": crate::params::CHORD_ERROR_PATTERN}));
    }
    if let Some((_, values)) = crate::params::choices()
        .into_iter()
        .find(|(n, _)| *n == name)
    {
        return Some(json!({"type": "string", "enum": values}));
    }
    let r = crate::params::RANGES.iter().find(|r| r.name == name)?;
    let mut schema = json!({"type": if r.integer { "integer" } else { "number" }});
    if r.integer {
        schema["minimum"] = json!(r.min as u64);
        if let Some(m) = r.max {
            schema["maximum"] = json!(m as u64);
        }
    } else {
        let key = if r.exclusive_min {
            "exclusiveMinimum"
        } else {
            "minimum"
        };
        schema[key] = json!(r.min);
        if let Some(m) = r.max {
            schema["maximum"] = json!(m);
        }
    }
    Some(schema)
}

/// What the annotations cannot say: every query parameter's type, range or enumeration (also as
/// the multipart upload's text fields), and the server-sent events' format.
fn contract(doc: &mut serde_json::Value) {
    query_parameters(doc);
    multipart_fields(doc);
    let Some(paths) = doc.get_mut("paths").and_then(|p| p.as_object_mut()) else {
        return;
    };
    let events = "/v1/reconstructions/{id}/events";
    if let Some(ok) = paths
        .get_mut(events)
        .and_then(|i| i.pointer_mut("/get/responses/200"))
    {
        ok["content"] = serde_json::json!({
            "text/event-stream": {
                "schema": {
                    "type": "object",
                    "description": "A stream of server-sent events. Each event is `event: progress` (while the job is queued or running) or `event: done` (once, with the terminal state; the stream then ends), followed by `data: ` and the job as one line of JSON (schema JobView). Comment lines (`:`) keep the connection alive.",
                    "properties": {
                        "event": {"type": "string", "enum": ["progress", "done"]},
                        "data": {
                            "type": "string",
                            "contentMediaType": "application/json",
                            "description": "The job (schema JobView) as one line of JSON.",
                        },
                    },
                    "required": ["event", "data"],
                },
            }
        });
    }
}

/// Each query parameter's schema from [`parameter_schema`].
fn query_parameters(doc: &mut serde_json::Value) {
    let Some(paths) = doc.get_mut("paths").and_then(|p| p.as_object_mut()) else {
        return;
    };
    for item in paths.values_mut() {
        let Some(ops) = item.as_object_mut() else {
            continue;
        };
        for op in ops.values_mut() {
            let Some(params) = op.get_mut("parameters").and_then(|p| p.as_array_mut()) else {
                continue;
            };
            for p in params {
                if p["in"] != "query" {
                    continue;
                }
                if let Some(schema) = p["name"].as_str().and_then(parameter_schema) {
                    p["schema"] = schema;
                }
            }
        }
    }
}

/// The multipart upload takes the upload's query parameters as text fields too: each is a
/// property of `MultipartUpload` with the query's schema, and no other field is accepted.
fn multipart_fields(doc: &mut serde_json::Value) {
    let fields: Vec<(String, serde_json::Value)> = doc
        .pointer("/paths/~1v1~1reconstructions/post/parameters")
        .and_then(|p| p.as_array())
        .into_iter()
        .flatten()
        .filter(|p| p["in"] == "query")
        .filter_map(|p| Some((p["name"].as_str()?.to_string(), p["schema"].clone())))
        .collect();
    let Some(upload) = doc.pointer_mut("/components/schemas/MultipartUpload") else {
        return;
    };
    if let Some(props) = upload["properties"].as_object_mut() {
        for (name, schema) in fields {
            props.entry(name).or_insert(schema);
        }
    }
    upload["additionalProperties"] = serde_json::json!(false);
}
