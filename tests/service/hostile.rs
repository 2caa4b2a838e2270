//! The service as a hostile client meets it, on loopback where the transport matters:
//! budgets a request cannot lift, stalled and trickling uploads, degenerate uploads, impossible
//! parameters, a full disk, internal errors without server paths, token scope, parameter
//! conflicts, per-job memory and the synchronous `?wait` answers. Time bounds are generous
//! (several times the target) so a loaded two-core machine does not fail them; the measured
//! numbers are printed (`--nocapture`).

use crate::server_common;

use axum::http::StatusCode;
use server_common::*;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// `n` points on a line, as XYZ text.
fn line_xyz(n: usize) -> Vec<u8> {
    let mut s = String::with_capacity(n * 24);
    for i in 0..n {
        let t = i as f64 / n as f64;
        s.push_str(&format!("{t} {} {}\n", 2.0 * t, 1.0 - t));
    }
    s.into_bytes()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_cannot_lift_the_operators_limits() {
    let s = start(|c| {
        c.max_memory_mib = 256;
        c.max_resolution = 128;
    });
    let cloud = sphere_xyz(5000, 1);
    let t = Instant::now();
    // Before: accepted, and the server grew until the OS killed it.
    let a = post(
        &s.app,
        "/v1/reconstructions?support=1.0&max-memory-mib=4194304",
        "text/plain",
        cloud.clone(),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::UNPROCESSABLE_ENTITY),
        "system_too_large"
    );
    let msg = a.json()["error"]["message"].as_str().unwrap().to_string();
    assert!(msg.contains("MiB") && msg.contains("256"), "{msg}");
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=4096",
        "text/plain",
        cloud.clone(),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::UNPROCESSABLE_ENTITY),
        "system_too_large"
    );
    println!("two refusals in {:.2} s", t.elapsed().as_secs_f64());
    assert!(t.elapsed() < Duration::from_secs(20));
    assert!(s.state.jobs.list().is_empty(), "nothing was queued");
    // Lowering is allowed, and the job runs with the lower budget.
    let a = post(
        &s.app,
        "/v1/reconstructions?max-memory-mib=200&resolution=24&wait=60",
        "text/plain",
        sphere_xyz(500, 2),
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    let id = a.json()["id"].as_str().unwrap().to_string();
    let stored = std::fs::read_to_string(s.dir.path().join(&id).join("params.json")).unwrap();
    assert!(stored.contains("\"max-memory-mib\": 200"), "{stored}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn impossible_parameters_are_refused_at_submit_with_4xx() {
    let s = start(|c| c.max_memory_mib = 1024);
    let cloud = sphere_xyz(20_000, 3);
    let cases = [
        ("support=1e-300", 422, "unsuitable_parameter"),
        ("support=1.0", 422, "system_too_large"),
        ("neighbours=2000&max-memory-mib=64", 422, "system_too_large"),
        ("method=variational", 422, "system_too_large"),
        ("resolution=4096", 422, "system_too_large"),
        ("support=0.1&neighbours=30", 422, "conflicting_parameters"),
        ("method=mls&neighbours=30", 422, "conflicting_parameters"),
        (
            "method=variational&support=0.1",
            422,
            "conflicting_parameters",
        ),
    ];
    for (q, status, code) in cases {
        let t = Instant::now();
        let a = post(
            &s.app,
            &format!("/v1/reconstructions?{q}"),
            "text/plain",
            cloud.clone(),
        )
        .await;
        let secs = t.elapsed().as_secs_f64();
        println!("{q}: {} in {secs:.2} s", a.status);
        assert_eq!(
            a.expect_error(StatusCode::from_u16(status).unwrap()),
            code,
            "{q}"
        );
        assert!(secs < 20.0, "{q} took {secs} s");
    }
    assert!(s.state.jobs.list().is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn degenerate_uploads_fail_in_their_job_and_do_not_hold_up_others() {
    let s = start(|c| {
        c.max_points = 1_000_000;
        c.max_upload_bytes = 64 << 20;
    });
    let t = Instant::now();
    let a = post(
        &s.app,
        "/v1/reconstructions",
        "text/plain",
        line_xyz(300_000),
    )
    .await;
    let accept = t.elapsed().as_secs_f64();
    assert_eq!(
        a.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    let line_id = a.json()["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    let b = post(
        &s.app,
        "/v1/reconstructions?resolution=24&wait=60",
        "text/plain",
        sphere_xyz(500, 4),
    )
    .await;
    println!(
        "collinear 300k accepted in {accept:.2} s; the next job answered in {:.2} s",
        t.elapsed().as_secs_f64()
    );
    assert_eq!(b.status, StatusCode::OK);
    let line = wait_terminal(&s.app, &line_id, 60).await;
    assert_eq!(line["status"], "failed");
    assert_eq!(line["error"]["code"], "unreconstructable");
    assert!(
        line["error"]["message"].as_str().unwrap().contains("line"),
        "{line}"
    );
}

/// Sends the head of a POST whose body never comes (or trickles), and returns the stream.
async fn stalled_upload(addr: std::net::SocketAddr) -> tokio::net::TcpStream {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = format!(
        "POST /v1/reconstructions HTTP/1.1\r\nHost: {addr}\r\nContent-Type: text/plain\r\nContent-Length: 100000\r\n\r\n0 0 0\n"
    );
    s.write_all(head.as_bytes()).await.unwrap();
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stalled_and_trickling_clients_are_cut_off_and_do_not_block_uploads() {
    let state = start_on(&tempfile::tempdir().unwrap().keep(), |c| {
        c.workers = 1; // two receive slots
        c.idle_timeout = Duration::from_secs(2);
        c.min_upload_rate = 16 << 10;
        c.upload_slot_wait = Duration::from_secs(30);
    });
    let live = launch(state).await;
    let addr = live.addr;
    // Two stalled bodies take both slots; a third client trickles its body at 1 byte / 0.5 s.
    let mut stalled = vec![stalled_upload(addr).await, stalled_upload(addr).await];
    let trickle = tokio::spawn(async move {
        let mut s = stalled_upload(addr).await;
        for _ in 0..60 {
            tokio::time::sleep(Duration::from_millis(500)).await;
            if s.write_all(b"1").await.is_err() {
                break;
            }
        }
        let mut buf = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf)).await;
        split_response(&buf).0
    });
    // A header trickler: one byte per second, never a full head.
    let header_trickle = tokio::spawn(async move {
        let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
        let t = Instant::now();
        for b in b"GET /healthz HTTP/1.1\r\nX-Slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa" {
            if s.write_all(&[*b]).await.is_err() {
                break;
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
            let mut probe = [0u8; 1];
            if let Ok(Ok(0)) =
                tokio::time::timeout(Duration::from_millis(1), s.read(&mut probe)).await
            {
                break;
            }
        }
        t.elapsed().as_secs_f64()
    });
    tokio::time::sleep(Duration::from_millis(300)).await;
    let t = Instant::now();
    let (status, _, body) = raw_request(
        addr,
        "POST",
        "/v1/reconstructions?resolution=24",
        &[("Content-Type", "text/plain")],
        &sphere_xyz(500, 5),
    )
    .await;
    let normal = t.elapsed().as_secs_f64();
    println!("normal upload beside 3 stalled/trickling ones answered {status} in {normal:.2} s");
    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
    assert!(normal < 15.0, "took {normal} s");
    for s in &mut stalled {
        let mut buf = Vec::new();
        let r = tokio::time::timeout(Duration::from_secs(15), s.read_to_end(&mut buf)).await;
        assert!(r.is_ok(), "a stalled upload was never closed");
        let (code, _, body) = split_response(&buf);
        assert_eq!(code, 408, "{}", String::from_utf8_lossy(&body));
        assert!(String::from_utf8_lossy(&body).contains("upload_too_slow"));
    }
    assert_eq!(
        trickle.await.unwrap(),
        408,
        "the trickling upload is refused"
    );
    let closed_after = header_trickle.await.unwrap();
    println!("header trickler disconnected after {closed_after:.1} s");
    assert!(
        closed_after < 20.0,
        "header trickler kept for {closed_after} s"
    );
    // An idle keep-alive connection is closed too.
    let mut idle = tokio::net::TcpStream::connect(addr).await.unwrap();
    let t = Instant::now();
    let mut buf = Vec::new();
    let r = tokio::time::timeout(Duration::from_secs(20), idle.read_to_end(&mut buf)).await;
    assert!(r.is_ok(), "an idle connection was never closed");
    println!(
        "idle connection closed after {:.1} s",
        t.elapsed().as_secs_f64()
    );
    live.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn too_many_uploads_at_once_is_429_busy() {
    let state = start_on(&tempfile::tempdir().unwrap().keep(), |c| {
        c.workers = 1;
        c.idle_timeout = Duration::from_secs(10);
        c.upload_slot_wait = Duration::from_millis(500);
    });
    let live = launch(state).await;
    let _held = [
        stalled_upload(live.addr).await,
        stalled_upload(live.addr).await,
    ];
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (status, head, body) = raw_request(
        live.addr,
        "POST",
        "/v1/reconstructions",
        &[("Content-Type", "text/plain")],
        &sphere_xyz(100, 6),
    )
    .await;
    assert_eq!(status, 429, "{}", String::from_utf8_lossy(&body));
    assert!(String::from_utf8_lossy(&body).contains("\"busy\""));
    assert!(head.to_ascii_lowercase().contains("retry-after"));
    live.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn multipart_without_or_with_two_files_and_malformed_is_bad_multipart() {
    let s = start(|_| {});
    let b = "BoUnD";
    let part = |name: &str, file: bool, body: &str| {
        let fname = if file { "; filename=\"c.xyz\"" } else { "" };
        format!("--{b}\r\nContent-Disposition: form-data; name=\"{name}\"{fname}\r\n\r\n{body}\r\n")
    };
    let cloud = String::from_utf8(sphere_xyz(50, 7)).unwrap();
    let bodies = [
        format!("{}--{b}--\r\n", part("resolution", false, "24")),
        format!(
            "{}{}--{b}--\r\n",
            part("file", true, &cloud),
            part("file2", true, &cloud)
        ),
        "--BoUnD\r\nthis is not a part".to_string(),
    ];
    for body in bodies {
        let a = post(
            &s.app,
            "/v1/reconstructions",
            &format!("multipart/form-data; boundary={b}"),
            body,
        )
        .await;
        assert_eq!(a.expect_error(StatusCode::BAD_REQUEST), "bad_multipart");
    }
    let a = post(&s.app, "/v1/reconstructions", "multipart/form-data", "x").await;
    assert_eq!(a.expect_error(StatusCode::BAD_REQUEST), "bad_multipart");
    assert!(s.state.jobs.list().is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn internal_errors_name_no_server_path_and_carry_an_error_id() {
    let s = start(|_| {});
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=24&wait=60",
        "text/plain",
        sphere_xyz(400, 8),
    )
    .await;
    let id = a.json()["id"].as_str().unwrap().to_string();
    std::fs::remove_file(s.dir.path().join(&id).join("mesh.glb")).unwrap();
    let m = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.glb")).await;
    assert_eq!(
        m.expect_error(StatusCode::INTERNAL_SERVER_ERROR),
        "internal"
    );
    let text = String::from_utf8_lossy(&m.body).to_string();
    let dir = s.dir.path().display().to_string();
    assert!(!text.contains(&dir) && !text.contains("/tmp"), "{text}");
    assert!(text.contains("error id"), "{text}");
}

/// A tmpfs of `kib` KiB mounted on a fresh directory (root only; `None` where not allowed).
fn small_tmpfs(kib: u64) -> Option<tempfile::TempDir> {
    let dir = tempfile::tempdir().ok()?;
    let ok = std::process::Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
        .arg(dir.path())
        .status()
        .is_ok_and(|s| s.success());
    ok.then_some(dir)
}

fn unmount(dir: &tempfile::TempDir) {
    let _ = std::process::Command::new("umount")
        .arg(dir.path())
        .status();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_is_507_without_the_data_directory_in_the_answer() {
    let Some(disk) = small_tmpfs(256) else {
        println!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    };
    let state = start_on(disk.path(), |c| c.max_upload_bytes = 8 << 20);
    let app = rbfsurf::server::router(state.clone());
    let dir = disk.path().display().to_string();
    // The upload itself does not fit: refused at submit.
    let big = sphere_xyz(8000, 9);
    assert!(big.len() > 300 << 10);
    let a = post(&app, "/v1/reconstructions", "text/plain", big).await;
    let code = a.expect_error(StatusCode::INSUFFICIENT_STORAGE);
    let text = String::from_utf8_lossy(&a.body).to_string();
    println!("full disk at submit: 507 {text}");
    assert_eq!(code, "insufficient_storage");
    assert!(!text.contains(&dir), "{text}");
    // The input fits, the mesh does not: the job fails with 507 under `wait`.
    let a = post(
        &app,
        "/v1/reconstructions?resolution=160&wait=120",
        "text/plain",
        sphere_xyz(1500, 10),
    )
    .await;
    let text = String::from_utf8_lossy(&a.body).to_string();
    println!("full disk in the job: {} {text:.300}", a.status);
    assert_eq!(a.status, StatusCode::INSUFFICIENT_STORAGE, "{text}");
    assert_eq!(a.json()["error"]["code"], "insufficient_storage");
    assert_eq!(a.json()["job"]["status"], "failed");
    assert!(!text.contains(&dir), "{text}");
    drop(app);
    state.jobs.shutdown();
    unmount(&disk);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_token_listing_needs_it_and_the_scheme_is_case_insensitive() {
    let s = start(|c| c.token = Some("s3cret".into()));
    let list = get(&s.app, "/v1/reconstructions").await;
    assert_eq!(list.expect_error(StatusCode::UNAUTHORIZED), "unauthorized");
    let req = |auth: &str| {
        axum::http::Request::get("/v1/reconstructions")
            .header("authorization", auth)
            .body(axum::body::Body::empty())
            .unwrap()
    };
    for ok in ["Bearer s3cret", "bearer s3cret", "BEARER s3cret"] {
        assert_eq!(send(&s.app, req(ok)).await.status, StatusCode::OK, "{ok}");
    }
    for bad in ["Bearer wrong", "Basic s3cret", "s3cret"] {
        assert_eq!(
            send(&s.app, req(bad)).await.status,
            StatusCode::UNAUTHORIZED,
            "{bad}"
        );
    }
    // Per-job reads stay capability-style: the unguessable id is the key.
    let post_req = axum::http::Request::post("/v1/reconstructions?resolution=24&wait=60")
        .header("authorization", "bearer s3cret")
        .header("content-type", "text/plain")
        .body(axum::body::Body::from(sphere_xyz(300, 11)))
        .unwrap();
    let a = send(&s.app, post_req).await;
    assert_eq!(a.status, StatusCode::OK);
    let id = a.json()["id"].as_str().unwrap().to_string();
    assert_eq!(
        get(&s.app, &format!("/v1/reconstructions/{id}"))
            .await
            .status,
        StatusCode::OK
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_jobs_peak_memory_is_its_own_and_the_process_figure_is_beside_it() {
    let s = start(|_| {});
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=32&wait=60",
        "text/plain",
        sphere_xyz(3000, 12),
    )
    .await;
    assert_eq!(a.status, StatusCode::OK);
    let mem = &a.json()["report"]["memory"];
    let job = mem["peak_rss_mib"].as_f64().unwrap();
    let process = mem["process_peak_rss_mib"].as_f64().unwrap();
    println!("job peak {job:.1} MiB, process peak {process:.1} MiB");
    assert!(job >= 0.0 && job <= process, "{mem}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wait_answers_a_timed_out_job_with_422_and_the_job() {
    let s = start(|c| c.job_timeout = Duration::from_secs(1));
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=400&wait=60",
        "text/plain",
        sphere_xyz(20_000, 13),
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::UNPROCESSABLE_ENTITY,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    let v = a.json();
    assert_eq!(v["error"]["code"], "job_timeout");
    assert_eq!(v["job"]["status"], "failed");
}
