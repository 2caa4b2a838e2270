//! Early refusals as real clients meet them, on a loopback listener: Python's `urllib` (standard
//! library) and `requests` (installed from PyPI, pinned, into a virtual environment under the
//! target directory) send the whole multi-MiB body before they read, so the answer the server
//! gives from the headers must survive until they do. Also the bounds of that drain (a slow
//! refused body does not hold the server, and its connection closes in bounded time) and
//! `Expect: 100-continue`, over raw sockets.
//!
//! Without `python3` or PyPI, the Python tests are skipped with a message; under CI (`CI=true`)
//! they fail instead.

use crate::server_common;

use server_common::*;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// `requests` version installed into the test's virtual environment.
const REQUESTS: &str = "2.34.2";
const TOKEN: &str = "s3cret-token";

fn under_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Panics under CI, prints the reason otherwise (the caller then skips).
fn unavailable(what: &str) -> Option<PathBuf> {
    assert!(!under_ci(), "{what} (required under CI)");
    eprintln!("skipped: {what}");
    None
}

fn runs(python: &Path, code: &str) -> bool {
    std::process::Command::new(python)
        .args(["-c", code])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The system's `python3` (for `urllib`).
fn system_python() -> Option<PathBuf> {
    let p = PathBuf::from("python3");
    if runs(&p, "import urllib.request, json") {
        Some(p)
    } else {
        unavailable("no python3 on PATH")
    }
}

/// The virtual environment's interpreter with `requests` pinned, created when missing.
fn requests_python() -> Option<PathBuf> {
    static SETUP: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = SETUP.lock().unwrap_or_else(|p| p.into_inner());
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target"));
    let venv = target.join("python-clients-venv");
    let python = venv.join("bin/python");
    let check = format!("import requests; assert requests.__version__ == '{REQUESTS}'");
    if runs(&python, &check) {
        return Some(python);
    }
    let system = system_python()?;
    let made = std::process::Command::new(&system)
        .args(["-m", "venv"])
        .arg(&venv)
        .status()
        .is_ok_and(|s| s.success());
    if !made {
        return unavailable(&format!("python3 -m venv {} failed", venv.display()));
    }
    let pip = std::process::Command::new(venv.join("bin/pip"))
        .args(["install", "--quiet", &format!("requests=={REQUESTS}")])
        .status()
        .is_ok_and(|s| s.success());
    if !pip || !runs(&python, &check) {
        return unavailable(&format!("pip could not install requests=={REQUESTS}"));
    }
    Some(python)
}

/// `n` points on a unit sphere (Fibonacci lattice), XYZ text with 5 decimals (~26 bytes a point).
fn sphere_text(n: usize) -> Vec<u8> {
    let mut s = String::with_capacity(n * 28);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let t = golden * i as f64;
        s.push_str(&format!("{:.5} {:.5} {z:.5}\n", r * t.cos(), r * t.sin()));
    }
    s.into_bytes()
}

/// One request for the Python script, and what it must get.
struct Case {
    name: &'static str,
    url: String,
    headers: Vec<(&'static str, String)>,
    body: PathBuf,
    status: u16,
    code: Option<&'static str>,
}

/// Runs `clients.py` with `client` over `cases`: one JSON object per case.
async fn run_clients(python: &Path, client: &str, cases: &[Case]) -> Vec<serde_json::Value> {
    let input: Vec<serde_json::Value> = cases
        .iter()
        .map(|c| {
            let headers: serde_json::Map<String, serde_json::Value> = c
                .headers
                .iter()
                .map(|(k, v)| (k.to_string(), v.clone().into()))
                .collect();
            serde_json::json!({"name": c.name, "method": "POST", "url": c.url,
                "headers": headers, "body": c.body})
        })
        .collect();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/service/clients.py");
    let (python, client) = (python.to_path_buf(), client.to_string());
    let input = serde_json::to_vec(&input).unwrap();
    let out = tokio::task::spawn_blocking(move || {
        use std::io::Write;
        let mut child = std::process::Command::new(python)
            .arg(script)
            .arg(client)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        child.stdin.take().unwrap().write_all(&input).unwrap();
        child.wait_with_output().unwrap()
    })
    .await
    .unwrap();
    assert!(out.status.success(), "clients.py failed");
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// Every early refusal, and the limits checked after reading, for `client`; a multi-MiB body
/// each. Returns one line per case (printed by the caller).
async fn refusals_for(python: &Path, client: &str) -> Vec<String> {
    let files = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let p = files.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let big = sphere_text(200_000);
    let cloud = write("sphere200k.xyz", &big);
    let over = write("over-limit.xyz", &big.repeat(4));
    println!(
        "bodies: {} bytes (200k points), {} bytes (over the 16 MiB limit)",
        big.len(),
        big.len() * 4
    );
    // A: a token, room for no job; B: no token, at most 100k points.
    let a = start(|c| {
        c.token = Some(TOKEN.into());
        c.max_queue = 0;
        c.max_upload_bytes = 16 << 20;
        c.max_points = 300_000;
        c.max_resolution = 256;
    });
    let b = start(|c| c.max_upload_bytes = 16 << 20);
    let (la, lb) = (launch(a.state.clone()).await, launch(b.state.clone()).await);
    let bearer = ("Authorization", format!("Bearer {TOKEN}"));
    let text = ("Content-Type", "text/plain".to_string());
    let url = |addr: std::net::SocketAddr, q: &str| format!("http://{addr}/v1/reconstructions{q}");
    let case =
        |name, url, headers: Vec<(&'static str, String)>, body: &PathBuf, status, code| Case {
            name,
            url,
            headers,
            body: body.clone(),
            status,
            code: Some(code),
        };
    let cases = vec![
        case(
            "resolution over the limit",
            url(la.addr, "?resolution=4096"),
            vec![bearer.clone(), text.clone()],
            &cloud,
            422,
            "system_too_large",
        ),
        case(
            "bad parameter",
            url(la.addr, "?kernel=gauss"),
            vec![bearer.clone(), text.clone()],
            &cloud,
            400,
            "bad_parameter",
        ),
        case(
            "unsupported media type",
            url(la.addr, ""),
            vec![bearer.clone(), ("Content-Type", "image/png".into())],
            &cloud,
            415,
            "unsupported_media_type",
        ),
        case(
            "upload over the limit",
            url(la.addr, ""),
            vec![bearer.clone(), text.clone()],
            &over,
            413,
            "too_large",
        ),
        case(
            "missing token",
            url(la.addr, ""),
            vec![text.clone()],
            &cloud,
            401,
            "unauthorized",
        ),
        case(
            "wrong token",
            url(la.addr, ""),
            vec![("Authorization", "Bearer nope".into()), text.clone()],
            &cloud,
            401,
            "unauthorized",
        ),
        case(
            "queue full",
            url(la.addr, "?resolution=24"),
            vec![bearer.clone(), text.clone()],
            &cloud,
            429,
            "queue_full",
        ),
        case(
            "points over the limit",
            url(lb.addr, "?resolution=24"),
            vec![text.clone()],
            &cloud,
            413,
            "too_large",
        ),
    ];
    let seen = run_clients(python, client, &cases).await;
    assert_eq!(seen.len(), cases.len());
    let mut lines = Vec::new();
    let mut wrong = Vec::new();
    for (c, s) in cases.iter().zip(&seen) {
        let got = s["status"].as_u64().map(|v| v as u16);
        let body: serde_json::Value = serde_json::from_str(s["body"].as_str().unwrap_or(""))
            .unwrap_or(serde_json::Value::Null);
        let code = body["error"]["code"].as_str();
        let line = match got {
            Some(st) => format!(
                "{client}: {}: {st} {}",
                c.name,
                code.unwrap_or("(no JSON error)")
            ),
            None => format!("{client}: {}: raised {}", c.name, s["exception"]),
        };
        if got != Some(c.status) || code != c.code {
            wrong.push(format!("{line} (expected {} {:?})", c.status, c.code));
        }
        lines.push(line);
    }
    // The servers still answer, and nothing was queued on A.
    assert_eq!(
        raw_request(la.addr, "GET", "/healthz", &[], b"").await.0,
        200
    );
    assert!(a.state.jobs.list().is_empty());
    la.shutdown().await;
    lb.shutdown().await;
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    lines
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn urllib_gets_every_early_refusal_as_its_json_error() {
    let Some(python) = system_python() else {
        return;
    };
    for line in refusals_for(&python, "urllib").await {
        println!("{line}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_gets_every_early_refusal_as_its_json_error() {
    let Some(python) = requests_python() else {
        return;
    };
    for line in refusals_for(&python, "requests").await {
        println!("{line}");
    }
}

/// Reads from `s` until the end of a response head and its `Content-Length` body.
async fn read_response(s: &mut (impl AsyncReadExt + Unpin)) -> (u16, String, Vec<u8>) {
    let mut buf = Vec::new();
    let mut chunk = [0u8; 8192];
    loop {
        let (status, head, body) = split_response(&buf);
        let len = head.lines().find_map(|l| {
            l.to_ascii_lowercase()
                .strip_prefix("content-length:")
                .map(|v| v.trim().parse::<usize>().unwrap_or(0))
        });
        if status != 0 && status != 100 && len.is_some_and(|n| body.len() >= n) {
            return (status, head, body);
        }
        if status == 100 {
            return (status, head, body);
        }
        let n = s.read(&mut chunk).await.unwrap();
        if n == 0 {
            return split_response(&buf);
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

fn head_for(addr: std::net::SocketAddr, query: &str, len: u64, extra: &str) -> String {
    format!(
        "POST /v1/reconstructions{query} HTTP/1.1\r\nHost: {addr}\r\nContent-Type: text/plain\r\nContent-Length: {len}\r\n{extra}\r\n"
    )
}

/// Waits until the server closes `s` (read returns 0 or fails), at most `limit`; returns when.
async fn closed_within(s: &mut tokio::net::TcpStream, limit: Duration) -> Option<Duration> {
    let t = Instant::now();
    let mut sink = [0u8; 4096];
    let r = tokio::time::timeout(limit, async {
        loop {
            match s.read(&mut sink).await {
                Ok(0) | Err(_) => return,
                Ok(_) => {}
            }
        }
    })
    .await;
    r.ok().map(|()| t.elapsed())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_refused_body_does_not_hold_the_server() {
    let s = start(|c| {
        c.max_upload_bytes = 16 << 20;
        c.max_resolution = 256;
        c.linger = Duration::from_secs(2);
    });
    let live = launch(s.state.clone()).await;
    // Declares 8 MiB and sends 1 KiB every 20 ms (~50 KiB/s): answered at once, then drained
    // for at most the 2 s linger while the client keeps sending.
    let mut slow = tokio::net::TcpStream::connect(live.addr).await.unwrap();
    let t = Instant::now();
    slow.write_all(head_for(live.addr, "?resolution=4096", 8 << 20, "").as_bytes())
        .await
        .unwrap();
    let (mut rd, mut wr) = slow.into_split();
    let trickle = tokio::spawn(async move {
        let kib = [b'0'; 1024];
        let t = Instant::now();
        while wr.write_all(&kib).await.is_ok() {
            tokio::time::sleep(Duration::from_millis(20)).await;
            if t.elapsed() > Duration::from_secs(30) {
                return None;
            }
        }
        Some(t.elapsed())
    });
    let (status, head, body) = read_response(&mut rd).await;
    let answered = t.elapsed();
    assert_eq!(status, 422, "{head}");
    assert!(
        head.to_ascii_lowercase().contains("connection: close"),
        "{head}"
    );
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["error"]["code"], "system_too_large");
    // Meanwhile other clients are served.
    let t2 = Instant::now();
    assert_eq!(
        raw_request(live.addr, "GET", "/healthz", &[], b"").await.0,
        200
    );
    let (st, _, _) = raw_request(
        live.addr,
        "POST",
        "/v1/reconstructions?resolution=24",
        &[("Content-Type", "text/plain")],
        &sphere_text(2000),
    )
    .await;
    assert_eq!(st, 202);
    let others = t2.elapsed();
    // The drain ends within its bound: the server closes, the trickling client's writes fail.
    let mut rest = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(10), rd.read_to_end(&mut rest)).await;
    let write_failed = tokio::time::timeout(Duration::from_secs(10), trickle)
        .await
        .expect("the server kept reading the refused body for 10 s")
        .unwrap()
        .expect("the server kept reading the refused body for 30 s");
    println!(
        "answered in {:.3} s, two other requests in {:.3} s, closed after {:.2} s of trickling",
        answered.as_secs_f64(),
        others.as_secs_f64(),
        write_failed.as_secs_f64()
    );
    assert!(answered < Duration::from_secs(2), "{answered:?}");
    assert!(others < Duration::from_secs(5), "{others:?}");
    assert!(write_failed < Duration::from_secs(6), "{write_failed:?}");
    live.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn expect_continue_gets_the_refusal_instead_of_continue() {
    let s = start(|c| {
        c.max_upload_bytes = 16 << 20;
        c.max_resolution = 256;
    });
    let live = launch(s.state.clone()).await;
    let expect = "Expect: 100-continue\r\n";
    // Refused from the query: the final answer comes without `100 Continue`, and the server
    // closes without waiting for a body that the client will not send.
    let mut c = tokio::net::TcpStream::connect(live.addr).await.unwrap();
    c.write_all(head_for(live.addr, "?resolution=4096", 8 << 20, expect).as_bytes())
        .await
        .unwrap();
    let (status, head, body) = read_response(&mut c).await;
    assert_eq!(status, 422, "{head}");
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["error"]["code"], "system_too_large");
    let closed = closed_within(&mut c, Duration::from_secs(3)).await;
    assert!(
        closed.is_some(),
        "the connection stayed open waiting for the body"
    );
    // A body declared larger than twice the upload limit is not drained: 413, then closed.
    let mut c = tokio::net::TcpStream::connect(live.addr).await.unwrap();
    c.write_all(head_for(live.addr, "", 1 << 30, "").as_bytes())
        .await
        .unwrap();
    let (status, head, _) = read_response(&mut c).await;
    assert_eq!(status, 413, "{head}");
    assert!(
        closed_within(&mut c, Duration::from_secs(3))
            .await
            .is_some()
    );
    // An acceptable request: `100 Continue`, then the body, then 202.
    let cloud = sphere_text(2000);
    let mut c = tokio::net::TcpStream::connect(live.addr).await.unwrap();
    c.write_all(head_for(live.addr, "?resolution=24", cloud.len() as u64, expect).as_bytes())
        .await
        .unwrap();
    let (status, head, _) = read_response(&mut c).await;
    assert_eq!(status, 100, "{head}");
    c.write_all(&cloud).await.unwrap();
    let (status, head, body) = read_response(&mut c).await;
    assert_eq!(status, 202, "{head} {}", String::from_utf8_lossy(&body));
    live.shutdown().await;
}
