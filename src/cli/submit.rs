//! `rbfsurf submit FILE --server URL [--wait] [-o mesh.glb] [--report r.json] [--token T]
//! [--require-watertight] [parameters]`: posts a point file to a running `rbfsurf serve`, follows
//! the job, downloads the mesh. Exits non-zero when anything fails (for CI).

use super::http::{BaseUrl, HttpResponse, request};
use super::outln;
use crate::io::{MeshFormat, PointFormat, write_atomic};
use crate::params::{ReconOptions, ReconParams};
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Arguments of `submit`.
#[derive(Debug, Clone, clap::Args)]
pub struct SubmitArgs {
    /// Point file to upload (PLY, XYZ/PTS/TXT, CSV, OBJ).
    pub input: PathBuf,
    /// Server base URL, e.g. http://127.0.0.1:8080.
    #[arg(long)]
    pub server: String,
    /// Wait for the job to finish (implied by --output/--report).
    #[arg(long)]
    pub wait: bool,
    /// Download the mesh here (.glb, .ply or .obj).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Download the report JSON here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Bearer token (or set RBFSURF_TOKEN).
    #[arg(long)]
    pub token: Option<String>,
    /// Fail unless the mesh is watertight and manifold.
    #[arg(long)]
    pub require_watertight: bool,
    /// Give up waiting after this many seconds.
    #[arg(long, default_value_t = 3600)]
    pub timeout_s: u64,
    /// Reconstruction parameters (checked here first, then by the server).
    #[command(flatten)]
    pub options: ReconOptions,
}

fn media_type(path: &std::path::Path) -> &'static str {
    match PointFormat::from_path(path) {
        Some(PointFormat::Ply) => "application/ply",
        Some(PointFormat::Csv) => "text/csv",
        Some(PointFormat::Obj) => "model/obj",
        Some(PointFormat::Xyz | PointFormat::Pts) => "text/plain",
        Some(PointFormat::Las)
            if path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("laz")) =>
        {
            "application/vnd.laszip"
        }
        Some(PointFormat::Las) => "application/vnd.las",
        // E57 has no registered media type; the server recognises its signature.
        Some(PointFormat::E57) | None => "application/octet-stream",
    }
}

fn api_error(r: &HttpResponse) -> String {
    match r.json() {
        Ok(v) => format!(
            "HTTP {} {}: {}",
            r.status,
            v["error"]["code"].as_str().unwrap_or("?"),
            v["error"]["message"].as_str().unwrap_or("no message")
        ),
        Err(e) => e.to_string(),
    }
}

/// Runs `submit`.
pub fn run(a: &SubmitArgs) -> Result<()> {
    ReconParams::try_from(&a.options)?;
    let out_format = a.output.as_deref().map(MeshFormat::from_path).transpose()?;
    let base = BaseUrl::parse(&a.server)?;
    let bytes =
        std::fs::read(&a.input).with_context(|| format!("{}: cannot read", a.input.display()))?;
    let mut headers = vec![("Content-Type", media_type(&a.input).to_string())];
    if let Some(t) = a
        .token
        .clone()
        .or_else(|| std::env::var("RBFSURF_TOKEN").ok())
    {
        headers.push(("Authorization", format!("Bearer {t}")));
    }
    let query = serde_urlencoded::to_string(&a.options)?;
    let path = format!("/v1/reconstructions?{query}");
    let io_timeout = Duration::from_secs(120);
    let start = Instant::now();
    let r = loop {
        let r = request(&base, "POST", &path, &headers, &bytes, io_timeout)?;
        let retry = r.header("retry-after").and_then(|v| v.parse::<u64>().ok());
        match retry {
            Some(s) if r.status == 429 && start.elapsed().as_secs() + s < a.timeout_s => {
                eprintln!("server queue full; retrying in {s} s");
                std::thread::sleep(Duration::from_secs(s.clamp(1, 60)));
            }
            _ => break r,
        }
    };
    if r.status != 202 && r.status != 200 {
        bail!("{}: upload refused: {}", a.input.display(), api_error(&r));
    }
    let job = r.json()?;
    let id = job["id"]
        .as_str()
        .context("the server's answer has no job id")?
        .to_string();
    eprintln!("job {id} accepted ({} points)", job["input"]["points"]);
    if !(a.wait || a.output.is_some() || a.report.is_some()) {
        outln!("{id}");
        return Ok(());
    }
    let job = wait_job(&base, &id, &headers, Duration::from_secs(a.timeout_s))?;
    let status = job["status"].as_str().unwrap_or("?");
    if status != "succeeded" {
        bail!(
            "job {id} {status}: {}: {}",
            job["error"]["code"].as_str().unwrap_or("?"),
            job["error"]["message"].as_str().unwrap_or("no message")
        );
    }
    let mesh = &job["report"]["mesh"];
    eprintln!(
        "job {id} succeeded: {} triangles, {} component(s), watertight {}, manifold {}",
        mesh["triangles"], mesh["components"], mesh["watertight"], mesh["manifold"]
    );
    if let (Some(out), Some(fmt)) = (&a.output, out_format) {
        download(&base, &id, out, fmt, io_timeout)?;
    }
    if let Some(p) = &a.report {
        write_atomic(p, &serde_json::to_vec_pretty(&job["report"])?)?;
    }
    if a.require_watertight && !(mesh["watertight"] == true && mesh["manifold"] == true) {
        bail!("job {id}: the mesh is not watertight and manifold (--require-watertight)");
    }
    outln!("{id}");
    Ok(())
}

/// Polls `GET /v1/reconstructions/{id}?wait=30` until the job is terminal or `timeout` passes.
fn wait_job(
    base: &BaseUrl,
    id: &str,
    headers: &[(&str, String)],
    timeout: Duration,
) -> Result<serde_json::Value> {
    let start = Instant::now();
    let auth: Vec<(&str, String)> = headers
        .iter()
        .filter(|(k, _)| *k == "Authorization")
        .cloned()
        .collect();
    loop {
        let left = timeout.saturating_sub(start.elapsed()).as_secs().min(30);
        let r = request(
            base,
            "GET",
            &format!("/v1/reconstructions/{id}?wait={left}"),
            &auth,
            &[],
            Duration::from_secs(left + 60),
        )?;
        if r.status != 200 {
            bail!("job {id}: status request failed: {}", api_error(&r));
        }
        let job = r.json()?;
        match job["status"].as_str() {
            Some("queued" | "running") if start.elapsed() < timeout => continue,
            Some("queued" | "running") => bail!(
                "job {id}: still {} after {} s (--timeout-s)",
                job["status"],
                timeout.as_secs()
            ),
            _ => return Ok(job),
        }
    }
}

/// Downloads the mesh of job `id` in `fmt` to `out` (atomically).
fn download(
    base: &BaseUrl,
    id: &str,
    out: &std::path::Path,
    fmt: MeshFormat,
    timeout: Duration,
) -> Result<()> {
    let ext = match fmt {
        MeshFormat::Glb(_) => "glb",
        MeshFormat::Ply => "ply",
        MeshFormat::Obj => "obj",
    };
    let path = format!("/v1/reconstructions/{id}/mesh.{ext}");
    let r = request(base, "GET", &path, &[], &[], timeout)?;
    if r.status != 200 {
        bail!("downloading the mesh failed: {}", api_error(&r));
    }
    write_atomic(out, &r.body)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
