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
    components(schemas(super::error::ErrorBody, super::jobs::JobStatus, super::jobs::InputInfo))
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
}

/// The OpenAPI document.
pub fn openapi() -> utoipa::openapi::OpenApi {
    let mut api = api_router().split_for_parts().1;
    api.info.version = env!("CARGO_PKG_VERSION").to_string();
    api
}

/// The OpenAPI document as pretty JSON with a trailing newline (the proto/openapi.json format).
pub fn openapi_json() -> String {
    let mut s = openapi()
        .to_pretty_json()
        .unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"));
    s.push('\n');
    s
}
