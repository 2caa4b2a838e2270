//! HTTP handlers: `reconstructions` (the job API) and `meta` (health, OpenAPI, viewer page), plus
//! the helpers they share: bearer-token check, id parsing (ids are UUIDs; anything else is 404
//! before any file-system access) and the query-string → [`ReconOptions`] mapping (the command
//! line's names and validation, via serde).

pub(crate) mod meta;
pub mod reconstructions;
pub(crate) mod upload;
pub(crate) mod volume;

use super::error::ApiError;
use crate::job::{Job, JobView, ServerConfig};
use crate::params::{ReconOptions, ReconParams};
use axum::http::{HeaderMap, StatusCode, header};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use uuid::Uuid;

/// A job as answered by the API: its state, the report once it succeeded, and links.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct JobResponse {
    /// The job state.
    #[serde(flatten)]
    pub job: JobView,
    /// URL of this job (poll it, or add `?wait=SECONDS`).
    pub status_url: String,
    /// URLs of the related resources.
    pub links: JobLinks,
    /// The reconstruction report (the contract: docs/report.md) once the job succeeded.
    #[schema(value_type = Option<Object>)]
    pub report: Option<serde_json::Value>,
}

/// Related resources of a job.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct JobLinks {
    /// Server-sent events with progress.
    pub events: String,
    /// The mesh as binary glTF (also `mesh.ply`, `mesh.obj`).
    pub mesh: String,
    /// The report JSON.
    pub report: String,
}

/// `?wait=SECONDS` of the job endpoints.
#[derive(Debug, Clone, Default, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct WaitQuery {
    /// Hold the answer until the job finishes or this many seconds pass (capped by the server).
    pub wait: Option<f64>,
}

/// Builds the API answer for `job`; `report` is read by the caller when the job succeeded.
pub fn job_response(view: JobView, report: Option<serde_json::Value>) -> JobResponse {
    let base = format!("/v1/reconstructions/{}", view.id);
    JobResponse {
        status_url: base.clone(),
        links: JobLinks {
            events: format!("{base}/events"),
            mesh: format!("{base}/mesh.glb"),
            report: format!("{base}/report"),
        },
        job: view,
        report,
    }
}

/// 401 unless the request carries `Authorization: Bearer <token>` (when a token is configured).
/// The scheme name is case-insensitive (RFC 7235 §2.1).
pub fn authorize(token: Option<&str>, headers: &HeaderMap) -> Result<(), ApiError> {
    let Some(token) = token else {
        return Ok(());
    };
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|s| {
            let s = s.trim_start();
            let (scheme, rest) = s.split_at_checked(6)?;
            (scheme.eq_ignore_ascii_case("bearer") && rest.starts_with(' ')).then_some(rest)
        })
        .map(str::trim);
    match given {
        Some(g) if constant_time_eq(g.as_bytes(), token.as_bytes()) => Ok(()),
        Some(_) => Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "the bearer token is wrong; send Authorization: Bearer <the server's token>",
        )),
        None => Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "this server requires a token to submit, cancel, delete and list jobs; send Authorization: Bearer <token>",
        )),
    }
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Parses a job id; anything but a UUID (path tricks included) is an unknown job.
pub fn parse_id(raw: &str) -> Result<Uuid, ApiError> {
    Uuid::parse_str(raw).map_err(|_| ApiError::not_found("job"))
}

/// Looks a job up by its raw path segment.
pub fn find_job(st: &super::AppState, raw: &str) -> Result<Arc<Job>, ApiError> {
    let id = parse_id(raw)?;
    st.jobs.get(id).ok_or_else(|| ApiError::not_found("job"))
}

/// Name/value pairs of a query string or of multipart text fields.
pub type Pairs = Vec<(String, String)>;

/// Decodes a raw query string into pairs (400 on malformed encoding).
pub fn query_pairs(raw: Option<&str>) -> Result<Pairs, ApiError> {
    serde_urlencoded::from_str(raw.unwrap_or(""))
        .map_err(|e| ApiError::bad_parameter(format!("malformed query string: {e}")))
}

/// Splits off `wait` and converts the remaining pairs into validated options and parameters.
/// Same names, spellings and ranges as the command line; unknown names are refused. The
/// operator's limits are ceilings: the memory budget is the smaller of the request's and the
/// server's (stored in the returned options), a resolution above the server's is refused (422).
pub fn parse_params(
    pairs: &[(String, String)],
    cfg: &ServerConfig,
) -> Result<(ReconOptions, ReconParams, f64), ApiError> {
    let mut wait = 0.0;
    let mut rest: Vec<&(String, String)> = Vec::new();
    for p in pairs {
        if p.0 == "wait" {
            wait =
                p.1.parse::<f64>()
                    .ok()
                    .filter(|w| w.is_finite() && *w >= 0.0)
                    .ok_or_else(|| {
                        ApiError::bad_parameter(format!(
                            "invalid parameter wait = {}: seconds, a number >= 0",
                            p.1
                        ))
                    })?;
        } else {
            check_spelling(&p.0, &p.1)?;
            rest.push(p);
        }
    }
    check_conflicts(&rest)?;
    let encoded =
        serde_urlencoded::to_string(&rest).map_err(|e| ApiError::bad_parameter(e.to_string()))?;
    let mut options: ReconOptions = serde_urlencoded::from_str(&encoded).map_err(|e| {
        ApiError::bad_parameter(format!(
            "invalid parameters: {e} (names and values as on the command line, e.g. resolution=64&kernel=wendland-c2)"
        ))
    })?;
    ReconParams::try_from(&options)?;
    options.max_memory_mib = Some(
        options
            .max_memory_mib
            .map_or(cfg.max_memory_mib, |m| m.min(cfg.max_memory_mib)),
    );
    let params = ReconParams::try_from(&options)?;
    super::feasibility::check_request(&params, cfg)?;
    Ok((options, params, wait))
}

/// 422 `conflicting_parameters` for pairs that are each valid but cannot go together (the
/// OpenAPI document cannot express that between query parameters, so this is 422, not 400):
/// a parameter given twice (in the query and as a multipart field, or twice in either), `support`
/// with `neighbours`, and either with a method other than `csrbf`.
fn check_conflicts(pairs: &[&(String, String)]) -> Result<(), ApiError> {
    let has = |n: &str| pairs.iter().any(|p| p.0 == n);
    let conflict = |m: &str| {
        Err(ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "conflicting_parameters",
            m.to_string(),
        ))
    };
    if let Some((i, p)) =
        (pairs.iter().enumerate()).find(|(i, p)| pairs[..*i].iter().any(|q| q.0 == p.0))
    {
        let first = pairs
            .iter()
            .take(i)
            .find(|q| q.0 == p.0)
            .map_or("", |q| q.1.as_str());
        return conflict(&format!(
            "parameter {} is given twice ({first:?} and {:?}; the query and multipart fields are one set): give it once",
            p.0, p.1
        ));
    }
    if has("support") && has("neighbours") {
        return conflict(
            "support (a radius) and neighbours (a count) both choose the support: give one of them",
        );
    }
    let global = pairs
        .iter()
        .any(|p| p.0 == "method" && matches!(p.1.as_str(), "variational" | "mls"));
    if global && (has("support") || has("neighbours")) {
        return conflict(
            "support and neighbours apply to method csrbf only (variational and mls choose their own scale): drop them or use method=csrbf",
        );
    }
    Ok(())
}

/// The API takes exactly the spellings its OpenAPI document lists (the command line is more
/// lenient with case and aliases): choices from [`crate::params::choices`], `blocks` by
/// [`crate::params::BLOCKS_PATTERN`], `chord-error` by [`crate::params::CHORD_ERROR_PATTERN`].
fn check_spelling(name: &str, value: &str) -> Result<(), ApiError> {
    if name == "chord-error" && !crate::params::chord_error_spelled(value) {
        return Err(ApiError::bad_parameter(format!(
            "invalid parameter chord-error = {value}: auto, off or a fraction of the point spacing in (0, 2] (a decimal number, e.g. 0.1)"
        )));
    }
    if name == "blocks" {
        let number = (4..=9).contains(&value.len())
            && value.bytes().all(|b| b.is_ascii_digit())
            && !value.starts_with('0');
        if !(number || value == "auto" || value == "none") {
            return Err(ApiError::bad_parameter(format!(
                "invalid parameter blocks = {value}: auto, none or a number of points per block from 1000 to 999999999"
            )));
        }
    }
    if let Some((_, values)) = crate::params::choices()
        .into_iter()
        .find(|(n, _)| *n == name)
        && !values.contains(&value)
    {
        return Err(ApiError::bad_parameter(format!(
            "invalid parameter {name} = {value}: one of {}",
            values.join(", ")
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairs(q: &str) -> Pairs {
        query_pairs(Some(q)).unwrap()
    }

    fn parse(q: &str) -> Result<(ReconOptions, ReconParams, f64), ApiError> {
        parse_params(&pairs(q), &ServerConfig::default())
    }

    #[test]
    fn query_maps_to_the_shared_options() {
        let (o, p, w) = parse("resolution=32&kernel=wendland-c4&wait=2.5").unwrap();
        assert_eq!(o.resolution, Some(32));
        assert_eq!(p.resolution, Some(32));
        assert_eq!(p.kernel.to_string(), "wendland-c4");
        assert_eq!(w, 2.5);
        for bad in [
            "resolution=2",
            "resolution=abc",
            "kernel=gauss",
            "bogus=1",
            "wait=-1",
            "wait=nan",
            "support=-1",
            "max-memory-mib=4194305",
            "ordering=BFS",
            "index=kd-tree",
            "blocks=999",
            "blocks=01000",
        ] {
            let e = parse(bad).unwrap_err();
            assert_eq!(e.status, StatusCode::BAD_REQUEST, "{bad}");
            assert_eq!(e.body.code, "bad_parameter", "{bad}");
        }
    }

    #[test]
    fn conflicting_pairs_are_422() {
        for q in [
            "support=0.1&support=0.2",
            "support=0.1&neighbours=20",
            "method=mls&neighbours=20",
            "method=variational&support=0.2",
        ] {
            let e = parse(q).unwrap_err();
            assert_eq!(
                (e.status.as_u16(), e.body.code.as_str()),
                (422, "conflicting_parameters"),
                "{q}"
            );
        }
    }

    #[test]
    fn the_operators_limits_are_ceilings() {
        let cfg = ServerConfig {
            max_memory_mib: 512,
            max_resolution: 256,
            ..Default::default()
        };
        let (o, p, _) = parse_params(&pairs("max-memory-mib=4194304"), &cfg).unwrap();
        assert_eq!((o.max_memory_mib, p.max_memory_mib), (Some(512), 512));
        let (_, p, _) = parse_params(&pairs("max-memory-mib=100"), &cfg).unwrap();
        assert_eq!(p.max_memory_mib, 100);
        let (_, p, _) = parse_params(&pairs(""), &cfg).unwrap();
        assert_eq!(p.max_memory_mib, 512);
        let e = parse_params(&pairs("resolution=257"), &cfg).unwrap_err();
        assert_eq!(
            (e.status.as_u16(), e.body.code.as_str()),
            (422, "system_too_large")
        );
        parse_params(&pairs("resolution=256"), &cfg).unwrap();
    }

    #[test]
    fn ids_must_be_uuids_and_tokens_must_match() {
        assert!(parse_id("../../etc/passwd").is_err());
        assert!(parse_id("%2e%2e").is_err());
        let id = Uuid::new_v4();
        assert_eq!(parse_id(&id.to_string()).unwrap(), id);
        let mut h = HeaderMap::new();
        assert!(authorize(None, &h).is_ok());
        assert_eq!(
            authorize(Some("s3"), &h).unwrap_err().status,
            StatusCode::UNAUTHORIZED
        );
        h.insert(header::AUTHORIZATION, "Bearer s4".parse().unwrap());
        assert!(authorize(Some("s3"), &h).is_err());
        h.insert(header::AUTHORIZATION, "Bearer s3".parse().unwrap());
        assert!(authorize(Some("s3"), &h).is_ok());
        for ok in ["bearer s3", "BEARER s3", "BeArEr  s3 "] {
            h.insert(header::AUTHORIZATION, ok.parse().unwrap());
            assert!(authorize(Some("s3"), &h).is_ok(), "{ok}");
        }
        for bad in ["Bearers3", "Basic s3", "s3", "Bearer"] {
            h.insert(header::AUTHORIZATION, bad.parse().unwrap());
            assert!(authorize(Some("s3"), &h).is_err(), "{bad}");
        }
    }
}
