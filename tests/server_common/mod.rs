//! Helpers for the HTTP tests: a server state on a temporary data directory, one-shot requests
//! through the router (no sockets), synthetic clouds as XYZ text.
#![allow(dead_code)]

use axum::Router;
use axum::body::Body;
use axum::http::{HeaderMap, Request, StatusCode};
use rbfsurf::geometry::synthetic::Shape;
use rbfsurf::job::ServerConfig;
use rbfsurf::server::{AppState, router};
use std::time::Duration;
use tower::ServiceExt;

/// A running job manager on its own data directory.
pub struct TestServer {
    pub state: AppState,
    pub app: Router,
    pub dir: tempfile::TempDir,
}

/// Starts a server; `tweak` adjusts the configuration (data_dir is set to a temporary directory).
pub fn start(tweak: impl FnOnce(&mut ServerConfig)) -> TestServer {
    let dir = tempfile::tempdir().unwrap();
    let state = start_on(dir.path(), tweak);
    TestServer {
        app: router(state.clone()),
        state,
        dir,
    }
}

/// Starts a server on an existing data directory.
pub fn start_on(path: &std::path::Path, tweak: impl FnOnce(&mut ServerConfig)) -> AppState {
    let mut cfg = ServerConfig {
        data_dir: path.to_path_buf(),
        workers: 1,
        max_queue: 8,
        max_upload_bytes: 8 << 20,
        max_points: 100_000,
        job_timeout: Duration::from_secs(60),
        ..Default::default()
    };
    tweak(&mut cfg);
    AppState::start(cfg).unwrap()
}

/// An answer: status, headers, body.
pub struct Answer {
    pub status: StatusCode,
    pub headers: HeaderMap,
    pub body: Vec<u8>,
}

impl Answer {
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "{}: not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }

    /// Asserts the status and the `{"error":{"code","message"}}` shape; returns the code.
    pub fn expect_error(&self, status: StatusCode) -> String {
        assert_eq!(
            self.status,
            status,
            "body: {}",
            String::from_utf8_lossy(&self.body)
        );
        assert_eq!(
            self.headers.get("content-type").unwrap(),
            "application/json",
            "error bodies are JSON"
        );
        let v = self.json();
        let msg = v["error"]["message"].as_str().unwrap();
        assert!(!msg.is_empty());
        v["error"]["code"].as_str().unwrap().to_string()
    }
}

/// Sends one request through the router.
pub async fn send(app: &Router, req: Request<Body>) -> Answer {
    let resp = app.clone().oneshot(req).await.unwrap();
    let status = resp.status();
    let headers = resp.headers().clone();
    let body = axum::body::to_bytes(resp.into_body(), usize::MAX)
        .await
        .unwrap()
        .to_vec();
    Answer {
        status,
        headers,
        body,
    }
}

pub async fn get(app: &Router, uri: &str) -> Answer {
    send(app, Request::get(uri).body(Body::empty()).unwrap()).await
}

pub async fn post(app: &Router, uri: &str, ctype: &str, body: impl Into<Body>) -> Answer {
    let req = Request::post(uri)
        .header("content-type", ctype)
        .body(body.into())
        .unwrap();
    send(app, req).await
}

pub async fn delete(app: &Router, uri: &str) -> Answer {
    send(app, Request::delete(uri).body(Body::empty()).unwrap()).await
}

/// `n` points on the unit sphere with normals, as 6-column XYZ text.
pub fn sphere_xyz(n: usize, seed: u64) -> Vec<u8> {
    let pc = Shape::by_name("sphere").unwrap().sample(n, seed);
    let normals = pc.normals.unwrap();
    let mut s = String::new();
    for (p, q) in pc.points.iter().zip(&normals) {
        s.push_str(&format!(
            "{} {} {} {} {} {}\n",
            p[0], p[1], p[2], q[0], q[1], q[2]
        ));
    }
    s.into_bytes()
}

/// Polls a job until it reaches a terminal state (or panics after `secs`).
pub async fn wait_terminal(app: &Router, id: &str, secs: u64) -> serde_json::Value {
    let a = get(app, &format!("/v1/reconstructions/{id}?wait={secs}")).await;
    assert_eq!(a.status, StatusCode::OK);
    let v = a.json();
    let s = v["status"].as_str().unwrap();
    assert!(
        !matches!(s, "queued" | "running"),
        "job {id} still {s} after {secs} s"
    );
    v
}

/// A server on a real loopback listener: its address, a stop trigger and the serving task.
pub struct Live {
    pub addr: std::net::SocketAddr,
    pub stop: Option<tokio::sync::oneshot::Sender<()>>,
    pub task: tokio::task::JoinHandle<()>,
}

impl Live {
    /// Stops the server and waits for it.
    pub async fn shutdown(mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        let _ = self.task.await;
    }
}

/// Serves `state` on 127.0.0.1 (an ephemeral port) until [`Live::shutdown`].
pub async fn launch(state: AppState) -> Live {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        rbfsurf::server::serve_on(listener, state, async move {
            let _ = rx.await;
        })
        .await
        .unwrap();
    });
    Live {
        addr,
        stop: Some(tx),
        task,
    }
}

/// One HTTP/1.1 request on a fresh connection (`Connection: close`): status, head, body.
pub async fn raw_request(
    addr: std::net::SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> (u16, String, Vec<u8>) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(body).await.unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).await.unwrap();
    split_response(&buf)
}

/// Status, head and body of a raw HTTP/1.1 response (status 0 when there is none).
pub fn split_response(buf: &[u8]) -> (u16, String, Vec<u8>) {
    let Some(split) = buf.windows(4).position(|w| w == b"\r\n\r\n") else {
        return (0, String::from_utf8_lossy(buf).to_string(), Vec::new());
    };
    let head = String::from_utf8_lossy(&buf[..split]).to_string();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    (status, head, buf[split + 4..].to_vec())
}
