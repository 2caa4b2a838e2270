//! Cancel and time limits inside long stages: a dense variational factorisation and a
//! CSRBF assembly with a large support stop within a second of the timeout or the DELETE (the
//! assertions allow 3 s on a loaded machine; the measured delay is printed), and DELETE right after
//! POST never ends `succeeded`.

use crate::server_common;

use axum::http::StatusCode;
use server_common::*;
use std::time::{Duration, Instant};

/// Posts and returns the job id (202 expected).
async fn submit(app: &axum::Router, query: &str, body: Vec<u8>) -> String {
    let a = post(
        app,
        &format!("/v1/reconstructions?{query}"),
        "text/plain",
        body,
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    a.json()["id"].as_str().unwrap().to_string()
}

/// Polls until the job reaches `stage` (or ends); returns its state then.
async fn until_stage(app: &axum::Router, id: &str, stage: &str) -> serde_json::Value {
    for _ in 0..1200 {
        let v = get(app, &format!("/v1/reconstructions/{id}")).await.json();
        if v["stage"] == stage || !matches!(v["status"].as_str(), Some("queued" | "running")) {
            return v;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("job {id} never reached {stage}");
}

/// Waits for the terminal state and returns it with the delay since `from`.
async fn ended(app: &axum::Router, id: &str, from: Instant) -> (serde_json::Value, f64) {
    let v = wait_terminal(app, id, 120).await;
    (v, from.elapsed().as_secs_f64())
}

/// The two heavy tests of this file take their turns: each allocates hundreds of MB and keeps both
/// cores busy, and an abandoned factorisation runs on in the background after its job ends.
static HEAVY: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dense_factorisation_stops_at_the_timeout_and_at_a_cancel() {
    let _turn = HEAVY.lock().await;
    // 4,500 points → ~9,000 unknowns: the LBLᵀ alone takes several seconds (20 s measured on 2
    // loaded cores). The cancel runs first, on a machine no abandoned factorisation loads yet; the
    // job has no tight limit, so it surely reaches the factorisation.
    let cloud = sphere_xyz(4500, 21);
    let s = start(|c| c.job_timeout = Duration::from_secs(120));
    let id = submit(&s.app, "method=variational&resolution=16", cloud.clone()).await;
    let v = until_stage(&s.app, &id, "factor").await;
    assert_eq!(v["stage"], "factor", "{v}");
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let t = Instant::now();
    let d = delete(&s.app, &format!("/v1/reconstructions/{id}")).await;
    assert_eq!(d.status, StatusCode::ACCEPTED);
    let (v, secs) = ended(&s.app, &id, t).await;
    println!("variational cancel during factor: cancelled after {secs:.2} s");
    assert_eq!(v["status"], "cancelled", "{v}");
    assert!(secs < 3.0, "cancel took {secs} s");

    // The time limit counts from the job's start, so on a loaded machine (the abandoned
    // factorisation above runs on) the stages before the factorisation may use it up: then the
    // limit doubles and the job runs again, until one run is stopped inside the factorisation.
    // Every run must honour its limit.
    let mut stopped_in_factor = false;
    for limit in [3u64, 6, 12] {
        let s = start(|c| c.job_timeout = Duration::from_secs(limit));
        let id = submit(&s.app, "method=variational&resolution=16", cloud.clone()).await;
        let (v, _) = ended(&s.app, &id, Instant::now()).await;
        assert_eq!(v["status"], "failed", "{v}");
        assert_eq!(v["error"]["code"], "job_timeout", "{v}");
        let run_s = (v["finished_at"].as_u64().unwrap() - v["started_at"].as_u64().unwrap()) as f64;
        println!(
            "variational timeout {limit} s: the job ran {run_s} s (whole seconds), stopped in {}",
            v["stage"]
        );
        assert!(
            run_s <= (limit + 3) as f64,
            "ran {run_s} s with a {limit} s limit"
        );
        if v["stage"] == "factor" {
            stopped_in_factor = true;
            break;
        }
    }
    assert!(
        stopped_in_factor,
        "no run reached the factorisation before its limit"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_large_support_assembly_stops_at_a_cancel() {
    let _turn = HEAVY.lock().await;
    let s = start(|c| c.job_timeout = Duration::from_secs(120));
    // 30,000 points with R = 0.25: thousands of neighbours per point, a long assembly.
    let id = submit(&s.app, "support=0.25&resolution=16", sphere_xyz(30_000, 22)).await;
    let v = until_stage(&s.app, &id, "assemble").await;
    assert_eq!(v["stage"], "assemble", "{v}");
    tokio::time::sleep(Duration::from_millis(300)).await;
    let t = Instant::now();
    let d = delete(&s.app, &format!("/v1/reconstructions/{id}")).await;
    assert_eq!(d.status, StatusCode::ACCEPTED);
    let (v, secs) = ended(&s.app, &id, t).await;
    println!(
        "assembly cancel: cancelled after {secs:.2} s (stage {})",
        v["stage"]
    );
    assert_eq!(v["status"], "cancelled", "{v}");
    assert!(secs < 3.0, "cancel took {secs} s");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn delete_right_after_post_never_ends_succeeded() {
    let s = start(|c| c.workers = 2);
    let mut cancelled = 0;
    for k in 0..15 {
        let id = submit(&s.app, "resolution=16", sphere_xyz(200, 30 + k)).await;
        let d = delete(&s.app, &format!("/v1/reconstructions/{id}")).await;
        match d.status {
            StatusCode::ACCEPTED => {
                let v = wait_terminal(&s.app, &id, 60).await;
                assert_eq!(v["status"], "cancelled", "202 to DELETE, then {v}");
                let m = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.glb")).await;
                assert_eq!(
                    m.status,
                    StatusCode::CONFLICT,
                    "a cancelled job has no mesh"
                );
                cancelled += 1;
            }
            StatusCode::NO_CONTENT => {
                assert_eq!(
                    get(&s.app, &format!("/v1/reconstructions/{id}"))
                        .await
                        .status,
                    StatusCode::NOT_FOUND
                );
            }
            other => panic!("DELETE answered {other}"),
        }
    }
    println!("{cancelled} of 15 cancelled, the rest had finished and were deleted");
}
