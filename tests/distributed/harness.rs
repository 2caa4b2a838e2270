//! Processes for the distributed tests: a private `nats-server -js` on a free loopback port
//! with its own store directory, `rbfsurf serve --nats` nodes and `rbfsurf worker`s (the built
//! binary), a minimal HTTP GET, and the local runs the distributed ones are compared with.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_rbfsurf");
/// Ack wait of the tests' consumer: a dead worker's task is redelivered after this.
pub const ACK_WAIT_S: &str = "3";

/// The `nats-server` binary, or `None` (with a message) when it is missing outside CI; under
/// CI=true a missing server fails the test.
pub fn nats_binary() -> Option<PathBuf> {
    for p in [
        "/usr/sbin/nats-server",
        "/usr/bin/nats-server",
        "/usr/local/bin/nats-server",
    ] {
        if Path::new(p).exists() {
            return Some(PathBuf::from(p));
        }
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("nats-server is not installed (.ci/run installs it with apt-get)");
    }
    eprintln!("SKIPPED: nats-server is not installed (apt-get install nats-server)");
    None
}

/// A private JetStream server in a fresh temporary folder (the test's folder: logs, stores,
/// outputs); `None` when nats-server is missing outside CI (the test is then skipped).
pub fn private_nats() -> Option<(tempfile::TempDir, Nats)> {
    let bin = nats_binary()?;
    let tmp = tempfile::tempdir().unwrap();
    let nats = Nats::start(bin, tmp.path());
    Some((tmp, nats))
}

pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Waits until `proc`'s log holds `ready` (so the process itself listens, not another one on a
/// port reused between [`free_port`] and its bind); false when it ended first (the caller
/// retries on another port).
fn wait_ready(proc: &mut Proc, ready: &str, what: &str) -> bool {
    let t = Instant::now();
    loop {
        if proc.log().contains(ready) {
            return true;
        }
        if let Ok(Some(_)) = proc.child.try_wait() {
            return false;
        }
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "{what} not ready in 30 s:\n{}",
            proc.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Starts `make(port)` on free ports until one comes up (its log holds `ready`).
fn start_on_free_port(what: &str, ready: &str, mut make: impl FnMut(u16) -> Proc) -> (Proc, u16) {
    for _ in 0..5 {
        let port = free_port();
        let mut p = make(port);
        if wait_ready(&mut p, ready, what) {
            return (p, port);
        }
        eprintln!(
            "{what} on port {port} ended; trying another port:\n{}",
            p.log()
        );
    }
    panic!("{what} did not start on five ports");
}

/// A child process killed when dropped.
pub struct Proc {
    pub child: Child,
    pub log: PathBuf,
}

impl Proc {
    /// SIGKILL and reap.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
    /// The process's log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        self.kill();
    }
}

fn spawn(cmd: &mut Command, log: PathBuf) -> Proc {
    let f = std::fs::File::create(&log).unwrap();
    let child = cmd
        .stdin(Stdio::null())
        .stdout(f.try_clone().unwrap())
        .stderr(f)
        .spawn()
        .unwrap();
    Proc { child, log }
}

/// A private JetStream server.
pub struct Nats {
    bin: PathBuf,
    pub port: u16,
    store: PathBuf,
    dir: PathBuf,
    pub proc: Option<Proc>,
    starts: usize,
}

impl Nats {
    pub fn start(bin: PathBuf, dir: &Path) -> Nats {
        let mut n = Nats {
            bin,
            port: free_port(),
            store: dir.join("jetstream"),
            dir: dir.to_path_buf(),
            proc: None,
            starts: 0,
        };
        n.up();
        n
    }

    pub fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    /// Starts the server (again) on the same port and store.
    pub fn up(&mut self) {
        self.starts += 1;
        let log = self.dir.join(format!("nats-{}.log", self.starts));
        let mut cmd = Command::new(&self.bin);
        cmd.args([
            "-js",
            "-a",
            "127.0.0.1",
            "-p",
            &self.port.to_string(),
            "-sd",
        ])
        .arg(&self.store);
        let mut p = spawn(&mut cmd, log);
        if !wait_ready(&mut p, "Server is ready", "nats-server") {
            assert!(
                self.starts == 1,
                "nats-server did not restart on port {}:\n{}",
                self.port,
                p.log()
            );
            // The first start lost its port to another process: another one.
            self.port = free_port();
            return self.up();
        }
        self.proc = Some(p);
    }

    /// Stops it (SIGKILL: file storage must survive a crash).
    pub fn down(&mut self) {
        self.proc = None;
    }
}

pub fn worker(nats: &Nats, dir: &Path, name: &str, concurrency: usize) -> Proc {
    worker_with(nats, dir, name, concurrency, &[])
}

/// A worker with extra flags (`--spread-points N`).
pub fn worker_with(
    nats: &Nats,
    dir: &Path,
    name: &str,
    concurrency: usize,
    extra: &[&str],
) -> Proc {
    let mut cmd = Command::new(BIN);
    cmd.args([
        "worker",
        "--nats",
        &nats.url(),
        "--concurrency",
        &concurrency.to_string(),
    ])
    .args(extra)
    .env("RBFSURF_NATS_ACK_WAIT_S", ACK_WAIT_S)
    .env("RUST_LOG", "info");
    spawn(&mut cmd, dir.join(format!("{name}.log")))
}

/// An API node on a free port with its own data directory; returns it and its base URL.
pub fn serve(nats: &Nats, dir: &Path, name: &str) -> (Proc, String) {
    let data = dir.join(format!("{name}-data"));
    let (p, port) = start_on_free_port("serve --nats", "rbfsurf serve listening", |port| {
        let mut cmd = Command::new(BIN);
        cmd.args([
            "serve",
            "--nats",
            &nats.url(),
            "--addr",
            &format!("127.0.0.1:{port}"),
        ])
        .arg("--data-dir")
        .arg(&data)
        .env("RUST_LOG", "info");
        spawn(&mut cmd, dir.join(format!("{name}.log")))
    });
    (p, format!("http://127.0.0.1:{port}"))
}

/// An embedded service (`serve` without `--nats`) on a free port; returns it and its base URL.
pub fn serve_embedded(dir: &Path, name: &str) -> (Proc, String) {
    let (p, port) = start_on_free_port("serve", "rbfsurf serve listening", |port| {
        let mut cmd = Command::new(BIN);
        cmd.args(["serve", "--addr", &format!("127.0.0.1:{port}")])
            .arg("--data-dir")
            .arg(dir.join(format!("{name}-data")))
            .env("RUST_LOG", "info");
        spawn(&mut cmd, dir.join(format!("{name}.log")))
    });
    (p, format!("http://127.0.0.1:{port}"))
}

/// `GET base+path`: status and body.
pub fn get(base: &str, path: &str) -> (u16, Vec<u8>) {
    request("GET", base, path, None)
}

/// `POST base+path` with a JSON body: status and body as JSON.
pub fn post_json(base: &str, path: &str, body: &serde_json::Value) -> (u16, serde_json::Value) {
    let bytes = serde_json::to_vec(body).unwrap();
    let (status, body) = request("POST", base, path, Some(&bytes));
    (status, serde_json::from_slice(&body).unwrap_or_default())
}

/// `METHOD base+path` (with a JSON body if given): status and body.
pub fn request(method: &str, base: &str, path: &str, body: Option<&[u8]>) -> (u16, Vec<u8>) {
    let addr = base.trim_start_matches("http://");
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let body = body.unwrap_or_default();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n",
        body.len()
    )
    .unwrap();
    s.write_all(body).unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let end = raw.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&raw[..end]).to_string();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    let mut body = raw[end + 4..].to_vec();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        body = dechunk(&body);
    }
    (status, body)
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let Some(nl) = b.windows(2).position(|w| w == b"\r\n") else {
            return out;
        };
        let n = usize::from_str_radix(std::str::from_utf8(&b[..nl]).unwrap().trim(), 16).unwrap();
        if n == 0 {
            return out;
        }
        out.extend_from_slice(&b[nl + 2..nl + 2 + n]);
        b = &b[nl + 2 + n + 2..];
    }
}

pub fn get_json(base: &str, path: &str) -> serde_json::Value {
    let (status, body) = get(base, path);
    assert_eq!(status, 200, "{path}: {}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

/// Runs the binary to completion; panics with its output on failure.
pub fn rbfsurf(args: &[&str]) -> String {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "rbfsurf {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// `rbfsurf submit` in a child process (not waited for).
/// The tests' 30,000-point torus (`rbfsurf generate torus --seed 3`) as `dir/torus.ply`.
pub fn torus_cloud(dir: &Path) -> PathBuf {
    let path = dir.join("torus.ply");
    rbfsurf(&[
        "generate",
        "torus",
        "--points",
        "30000",
        "--seed",
        "3",
        "-o",
        path.to_str().unwrap(),
    ]);
    path
}

pub fn submit(base: &str, cloud: &Path, out: &Path, report: &Path, extra: &[&str]) -> Child {
    Command::new(BIN)
        .arg("submit")
        .arg(cloud)
        .args(["--server", base, "-o"])
        .arg(out)
        .arg("--report")
        .arg(report)
        .args(["--timeout-s", "300"])
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits for a `submit` child; panics with its output when it failed.
pub fn finish_submit(child: Child) {
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "submit failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

pub fn report(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// Waits until `cond` holds (polling every 100 ms), at most `secs`.
pub fn wait_until(secs: u64, what: &str, mut cond: impl FnMut() -> bool) {
    let t = Instant::now();
    while !cond() {
        assert!(
            t.elapsed() < Duration::from_secs(secs),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The ids of the jobs an API node lists.
pub fn job_ids(base: &str) -> Vec<String> {
    let v = get_json(base, "/v1/reconstructions");
    let list = v
        .as_array()
        .cloned()
        .or_else(|| v["jobs"].as_array().cloned());
    list.unwrap_or_default()
        .iter()
        .map(|j| j["id"].as_str().unwrap().to_string())
        .collect()
}
