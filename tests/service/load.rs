//! Load test (ignored by default; run with `cargo test --test service load:: -- --ignored --nocapture`):
//! a real listener on 127.0.0.1, 200 jobs from 20 concurrent clients (all must succeed, none lost,
//! memory bounded, p50/p95 latency printed), then a graceful restart in the middle of a batch of
//! 100 jobs (every stored job must finish after the restart).

use crate::server_common;

use rbfsurf::server::{AppState, serve_on};
use server_common::{sphere_xyz, start_on};
use std::collections::HashSet;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// One HTTP/1.1 request on a fresh connection: (status, retry-after seconds, body).
async fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    body: &[u8],
) -> (u16, Option<u64>, Vec<u8>) {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: text/plain\r\nContent-Length: {}\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(body).await.unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).await.unwrap();
    let split = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("no header end");
    let head = String::from_utf8_lossy(&buf[..split]).to_string();
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    let retry = head.lines().find_map(|l| {
        l.to_ascii_lowercase()
            .strip_prefix("retry-after:")
            .map(|v| v.trim().parse().unwrap_or(1))
    });
    (status, retry, buf[split + 4..].to_vec())
}

fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .map(|l| l.split_whitespace().nth(1).unwrap().parse::<f64>().unwrap() / 1024.0)
        })
        .unwrap_or(0.0)
}

async fn launch(
    state: AppState,
) -> (
    SocketAddr,
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<()>,
) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        serve_on(listener, state, async move {
            let _ = rx.await;
        })
        .await
        .unwrap();
    });
    (addr, tx, task)
}

/// POST until accepted (429 → wait Retry-After); returns the job JSON and the HTTP status.
async fn submit(addr: SocketAddr, query: &str, body: &[u8]) -> (u16, serde_json::Value) {
    loop {
        let (status, retry, b) =
            http(addr, "POST", &format!("/v1/reconstructions?{query}"), body).await;
        if status == 429 {
            tokio::time::sleep(Duration::from_secs(retry.unwrap_or(1).min(2))).await;
            continue;
        }
        return (status, serde_json::from_slice(&b).unwrap());
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
#[ignore = "load test: run explicitly (about a minute)"]
async fn two_hundred_jobs_from_twenty_clients_then_restart_mid_batch() {
    let dir = tempfile::tempdir().unwrap();
    let state = start_on(dir.path(), |c| {
        c.workers = 2;
        c.max_queue = 16;
    });
    let (addr, stop, task) = launch(state).await;
    let rss0 = rss_mib();
    let peak = Arc::new(AtomicU64::new(rss0 as u64));
    let p = peak.clone();
    let sampler = tokio::spawn(async move {
        loop {
            p.fetch_max(rss_mib() as u64, Ordering::Relaxed);
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    let t0 = Instant::now();
    let clients: Vec<_> = (0..20u64)
        .map(|c| {
            tokio::spawn(async move {
                let mut out = Vec::new();
                for k in 0..10u64 {
                    let cloud = sphere_xyz(400 + 20 * k as usize, c * 100 + k);
                    let t = Instant::now();
                    let (status, job) = submit(addr, "resolution=24&wait=300", &cloud).await;
                    out.push((status, job, t.elapsed().as_secs_f64()));
                }
                out
            })
        })
        .collect();
    let mut results = Vec::new();
    for c in clients {
        results.extend(c.await.unwrap());
    }
    let wall = t0.elapsed().as_secs_f64();
    sampler.abort();
    let ok = results
        .iter()
        .filter(|(s, j, _)| *s == 200 && j["status"] == "succeeded")
        .count();
    let ids: HashSet<String> = results
        .iter()
        .map(|r| r.1["id"].as_str().unwrap().to_string())
        .collect();
    let mut lat: Vec<f64> = results.iter().map(|r| r.2).collect();
    lat.sort_by(f64::total_cmp);
    let (_, _, list) = http(addr, "GET", "/v1/reconstructions", b"").await;
    let list: serde_json::Value = serde_json::from_slice(&list).unwrap();
    let stored = list
        .as_array()
        .unwrap()
        .iter()
        .filter(|j| j["status"] == "succeeded")
        .count();
    println!(
        "load: {ok}/200 succeeded, {} distinct ids, {stored} listed as succeeded; wall {wall:.1} s ({:.1} jobs/s); latency p50 {:.2} s, p95 {:.2} s, max {:.2} s; RSS {rss0:.0} MiB -> peak {} MiB",
        ids.len(),
        200.0 / wall,
        percentile(&lat, 0.5),
        percentile(&lat, 0.95),
        lat[lat.len() - 1],
        peak.load(Ordering::Relaxed)
    );
    assert_eq!(ok, 200);
    assert_eq!(ids.len(), 200);
    assert_eq!(stored, 200);
    assert!(peak.load(Ordering::Relaxed) < 2048, "memory not bounded");
    stop.send(()).unwrap();
    task.await.unwrap();

    // Restart in the middle of a batch: 100 queued jobs, stop after some finished, restart.
    let dir2 = tempfile::tempdir().unwrap();
    let state = start_on(dir2.path(), |c| {
        c.workers = 2;
        c.max_queue = 200;
    });
    let jobs = state.jobs.clone();
    let (addr, stop, task) = launch(state).await;
    let mut ids = Vec::new();
    for k in 0..100u64 {
        let (status, job) = submit(addr, "resolution=24", &sphere_xyz(500, 10_000 + k)).await;
        assert_eq!(status, 202);
        ids.push(job["id"].as_str().unwrap().to_string());
    }
    let count_done = |jobs: &rbfsurf::job::JobManager| {
        jobs.list()
            .iter()
            .filter(|j| j.status.is_terminal())
            .count()
    };
    while count_done(&jobs) < 30 {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let t = Instant::now();
    stop.send(()).unwrap();
    task.await.unwrap();
    let before = count_done(&jobs);
    println!(
        "restart: stopped after {before}/100 finished (graceful stop took {:.2} s)",
        t.elapsed().as_secs_f64()
    );
    drop(jobs);
    let state = start_on(dir2.path(), |c| {
        c.workers = 2;
        c.max_queue = 200;
    });
    let (addr, stop, task) = launch(state).await;
    let t = Instant::now();
    let mut succeeded = 0;
    for id in &ids {
        let (status, _, b) = http(
            addr,
            "GET",
            &format!("/v1/reconstructions/{id}?wait=300"),
            b"",
        )
        .await;
        assert_eq!(status, 200, "job {id} lost after the restart");
        let v: serde_json::Value = serde_json::from_slice(&b).unwrap();
        assert_eq!(v["status"], "succeeded", "{v}");
        let (s, _, glb) = http(
            addr,
            "GET",
            &format!("/v1/reconstructions/{id}/mesh.glb"),
            b"",
        )
        .await;
        assert_eq!(s, 200);
        assert!(rbfsurf::io::decode_glb(&glb).is_ok());
        succeeded += 1;
    }
    println!(
        "restart: after the restart all {succeeded}/100 jobs succeeded ({} re-queued ran in {:.1} s); none lost",
        100 - before,
        t.elapsed().as_secs_f64()
    );
    stop.send(()).unwrap();
    task.await.unwrap();
}
