//! The life of a job on NATS beyond reconstruction: composition and morph jobs run on workers
//! (equal to the embedded service's), finished jobs expire once across two API nodes and leave
//! nothing in the bucket or the object store, and a DELETE stops a running graph task.

use crate::harness::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A 3,000-point sphere (an in-memory CSRBF job: it has a saved field).
fn sphere(dir: &Path) -> PathBuf {
    let cloud = dir.join("sphere.ply");
    rbfsurf(&[
        "generate",
        "sphere",
        "--points",
        "3000",
        "-o",
        cloud.to_str().unwrap(),
    ]);
    cloud
}

/// `rbfsurf submit` to completion; returns the job id.
fn submit_id(base: &str, cloud: &Path, dir: &Path, name: &str, extra: &[&str]) -> String {
    let (out, rep) = (
        dir.join(format!("{name}.glb")),
        dir.join(format!("{name}.json")),
    );
    let child = submit(base, cloud, &out, &rep, extra);
    let done = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&done.stderr).to_string();
    assert!(done.status.success(), "submit failed: {err}");
    let line = err.lines().find(|l| l.starts_with("job ")).unwrap();
    line.split(' ').nth(1).unwrap().to_string()
}

/// Waits (at most `secs`) for job `id` to end on node `base`; returns its view. A job posted to
/// another API node is unknown here (404) until this node's watch of the job records delivers it.
fn wait_end(base: &str, id: &str, secs: u64) -> serde_json::Value {
    let t = Instant::now();
    loop {
        let (status, body) = get(base, &format!("/v1/reconstructions/{id}?wait=5"));
        if status == 404 && t.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(50));
            continue;
        }
        assert_eq!(status, 200, "{id}: {}", String::from_utf8_lossy(&body));
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        let status = v["status"].as_str().unwrap_or_default().to_string();
        if ["succeeded", "failed", "cancelled"].contains(&status.as_str()) {
            return v;
        }
        assert!(
            t.elapsed() < Duration::from_secs(secs),
            "job {id} still {status}"
        );
    }
}

/// POSTs a volume job; returns its id.
fn post_job(base: &str, path: &str, body: serde_json::Value) -> String {
    let (status, v) = post_json(base, path, &body);
    assert_eq!(status, 202, "{path}: {v}");
    v["id"].as_str().unwrap().to_string()
}

#[test]
fn compositions_and_morphs_run_on_workers_and_equal_the_embedded_services() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let _w = worker(&nats, dir, "w1", 1);
    let (_api_a, a) = serve(&nats, dir, "api-a");
    let (_api_b, b) = serve(&nats, dir, "api-b");
    let (_emb, e) = serve_embedded(dir, "embedded");
    let cloud = sphere(dir);
    let mut glbs = Vec::new();
    for (base, name) in [(&a, "dist"), (&e, "emb")] {
        let id = submit_id(base, &cloud, dir, name, &["--resolution", "32"]);
        let composition = post_job(
            base,
            "/v1/compositions",
            serde_json::json!({
                "expression": format!("difference({id}, sphere(0.5, 0, 0, 0.6))"),
                "resolution": 24,
            }),
        );
        let morph = post_job(
            base,
            "/v1/morphs",
            serde_json::json!({"a": id, "b": "sphere(0, 0, 0, 0.5)", "frames": 3, "resolution": 16}),
        );
        // The NATS jobs are read from the other API node: any node serves the results.
        let reader = if name == "dist" { &b } else { &e };
        let mut pair = Vec::new();
        for job in [composition, morph] {
            let v = wait_end(reader, &job, 120);
            assert_eq!(v["status"], "succeeded", "{name} {job}: {v}");
            assert!(v["triangles"].as_u64().unwrap() > 100, "{v}");
            let (status, glb) = get(reader, &format!("/v1/reconstructions/{job}/mesh.glb"));
            assert_eq!(status, 200);
            let (status, rep) = get(reader, &format!("/v1/reconstructions/{job}/report"));
            assert_eq!(status, 200, "{}", String::from_utf8_lossy(&rep));
            pair.push(glb);
        }
        glbs.push(pair);
    }
    assert!(
        glbs[0][0] == glbs[1][0],
        "the composition's GLB differs from the embedded service's"
    );
    assert!(
        glbs[0][1] == glbs[1][1],
        "the morph's GLB differs from the embedded service's"
    );
}

/// The number of messages a JetStream stream holds.
async fn stream_messages(js: &async_nats::jetstream::Context, name: &str) -> u64 {
    let mut s = js.get_stream(name).await.unwrap();
    s.info().await.unwrap().state.messages
}

/// An API node in this process (its expiry runs when the test calls it); returns its base URL.
fn node(
    rt: &tokio::runtime::Runtime,
    nats: &Nats,
    dir: &Path,
    name: &str,
) -> (rbfsurf::server::AppState, String) {
    let cfg = rbfsurf::job::ServerConfig {
        data_dir: dir.join(format!("{name}-data")),
        expire_after: Some(Duration::ZERO),
        ..Default::default()
    };
    let nc = rbfsurf::dist::NatsConfig {
        url: nats.url(),
        ack_wait: Duration::from_secs(3),
        ..Default::default()
    };
    let (state, _watcher) = rt
        .block_on(rbfsurf::server::nats::start_node(cfg, &nc))
        .unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let addr = listener.local_addr().unwrap();
    let app = rbfsurf::server::router(state.clone());
    rt.spawn(async move { axum::serve(listener, app).await });
    (state, format!("http://{addr}"))
}

#[test]
fn finished_jobs_expire_once_across_two_api_nodes_and_leave_nothing_behind() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let _w = worker(&nats, dir, "w1", 2);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let (node_a, a) = node(&rt, &nats, dir, "a");
    let (node_b, b) = node(&rt, &nats, dir, "b");
    // A whole job, a task-graph job (30,000-point torus out of core) and a composition.
    let cloud = sphere(dir);
    let whole = submit_id(&a, &cloud, dir, "whole", &["--resolution", "32"]);
    let torus = torus_cloud(dir);
    let graph = submit_id(
        &b,
        &torus,
        dir,
        "graph",
        &["--max-memory-mib", "110", "--resolution", "48"],
    );
    let composition = post_job(
        &a,
        "/v1/compositions",
        serde_json::json!({"expression": format!("union({whole}, sphere(1, 0, 0, 0.3))"), "resolution": 16}),
    );
    let ids = [whole, graph, composition];
    for id in &ids {
        for base in [&a, &b] {
            assert_eq!(wait_end(base, id, 120)["status"], "succeeded", "{id}");
        }
    }
    let graph_report = get_json(&a, &format!("/v1/reconstructions/{}/report", ids[1]));
    assert!(graph_report["blocks"].as_array().unwrap().len() >= 4);
    let js = rt.block_on(jetstream(&nats));
    let (objects, records) = ("OBJ_rbfsurf-objects", "KV_rbfsurf-jobs");
    assert!(rt.block_on(stream_messages(&js, objects)) > 0);

    // Both nodes sweep at once: each job is deleted by exactly one of them.
    let sweeps =
        [node_a.jobs.clone(), node_b.jobs.clone()].map(|m| std::thread::spawn(move || m.expire()));
    let deleted: usize = sweeps.into_iter().map(|h| h.join().unwrap()).sum();
    assert_eq!(deleted, ids.len(), "each job deleted once");
    for id in &ids {
        for (base, name) in [(&a, "a"), (&b, "b")] {
            wait_until(10, "the node to forget the expired job", || {
                get(base, &format!("/v1/reconstructions/{id}")).0 == 404
            });
            let (status, body) = get(base, &format!("/v1/reconstructions/{id}/mesh.glb"));
            assert_eq!(status, 404);
            let body: serde_json::Value = serde_json::from_slice(&body).unwrap();
            assert_eq!(
                body["error"]["code"], "not_found",
                "as the embedded service"
            );
            assert!(!dir.join(format!("{name}-data")).join(id).exists());
        }
    }
    // Nothing is left: no object, no chunk, no deletion marker, no record.
    assert_eq!(rt.block_on(stream_messages(&js, objects)), 0);
    assert_eq!(rt.block_on(stream_messages(&js, records)), 0);
    assert_eq!(node_a.jobs.expire() + node_b.jobs.expire(), 0);
}

/// A JetStream context on the test's server.
async fn jetstream(nats: &Nats) -> async_nats::jetstream::Context {
    async_nats::jetstream::new(async_nats::connect(nats.url()).await.unwrap())
}

/// The names of job `id`'s objects in the object store.
async fn objects_of(js: &async_nats::jetstream::Context, id: &str) -> Vec<String> {
    use futures_util::StreamExt;
    let os = js.get_object_store("rbfsurf-objects").await.unwrap();
    let mut list = os.list().await.unwrap();
    let mut names = Vec::new();
    while let Some(info) = list.next().await {
        let info = info.unwrap();
        if !info.deleted && info.name.starts_with(&format!("{id}/")) {
            names.push(info.name);
        }
    }
    names
}

/// Waits (at most 10 s) until job `id`'s only object is its input's one segment.
fn only_the_input_left(
    rt: &tokio::runtime::Runtime,
    js: &async_nats::jetstream::Context,
    id: &str,
) {
    let t = Instant::now();
    loop {
        let left = rt.block_on(objects_of(js, id));
        if left == vec![format!("{id}/input.ply/0")] {
            return;
        }
        assert!(t.elapsed().as_secs() < 10, "objects left: {left:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Lines of a log that start, or end (finished or failed), a task.
fn open_tasks(log: &str) -> i64 {
    let started = log.matches("task started").count() as i64;
    let ended = log.matches("task finished").count() + log.matches("task failed").count();
    started - ended as i64
}

/// DELETEs job `id` on `base` and waits (at most `secs`) for it to end cancelled; returns the
/// seconds from the DELETE to the cancelled state.
fn cancel_within(base: &str, id: &str, secs: u64) -> f64 {
    let (status, body) = request("DELETE", base, &format!("/v1/reconstructions/{id}"), None);
    assert_eq!(status, 202, "{}", String::from_utf8_lossy(&body));
    let deleted = Instant::now();
    wait_until(secs, "the job to end cancelled", || {
        get_json(base, &format!("/v1/reconstructions/{id}"))["status"] == "cancelled"
    });
    deleted.elapsed().as_secs_f64()
}

#[test]
fn a_delete_stops_running_jobs_within_seconds_and_leaves_workers_idle() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let w1 = worker(&nats, dir, "w1", 1);
    let w2 = worker(&nats, dir, "w2", 1);
    let (_api, a) = serve(&nats, dir, "api");
    let rt = tokio::runtime::Runtime::new().unwrap();
    let js = rt.block_on(jetstream(&nats));
    let torus = torus_cloud(dir);
    let logs = || w1.log() + &w2.log();
    let launch = |extra: &[&str]| {
        Command::new(BIN)
            .arg("submit")
            .arg(&torus)
            .args(["--server", &a])
            .args(extra)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };

    // The task graph, cancelled in its block phase: the job ends, its blocks' tasks are
    // skipped, and its intermediate values are removed (only the input, one segment, stays
    // until deletion).
    let mut graph = launch(&["--max-memory-mib", "110", "--resolution", "64"]);
    wait_until(120, "the block phase", || logs().contains("task=block"));
    let graph_id = job_ids(&a).pop().unwrap();
    let id = graph_id.clone();
    let graph_s = cancel_within(&a, &id, 5);
    wait_until(5, "both workers to be idle", || {
        open_tasks(&w1.log()) == 0 && open_tasks(&w2.log()) == 0
    });
    only_the_input_left(&rt, &js, &id);
    let _ = graph.wait();

    // A whole job, cancelled mid-task. The test profile is optimised: at resolution 64 the job
    // ends within 2 s on an idle machine, so it runs at 200 (about 6 s idle, 12 s under load).
    let mut whole = launch(&["--resolution", "200"]);
    wait_until(60, "the whole job to start", || {
        job_ids(&a).len() == 2 && logs().matches("task=start").count() >= 3
    });
    std::thread::sleep(Duration::from_millis(500));
    // The list is ordered by creation second, then id: both jobs may share a second.
    let id = job_ids(&a).into_iter().find(|j| *j != graph_id).unwrap();
    let whole_s = cancel_within(&a, &id, 5);
    wait_until(5, "both workers to be idle", || {
        open_tasks(&w1.log()) == 0 && open_tasks(&w2.log()) == 0
    });
    let all = logs();
    assert!(
        all.lines().any(|l| l.contains(&format!("job={id}"))
            && l.contains("task=start")
            && l.contains("code=cancelled")),
        "the whole job's task stopped mid-task:\n{all}"
    );
    let _ = whole.wait();
    eprintln!("cancelled {graph_s:.2} s (graph) and {whole_s:.2} s (whole job) after the DELETE");
}

/// A job cancelled while the workers prepare it by byte ranges: it ends cancelled and leaves
/// only its input (one segment), whichever prepare or block tasks were running.
#[test]
fn a_delete_during_a_prepare_by_ranges_leaves_only_the_input() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let ranges = ["--range-mib", "0.125"];
    let w1 = worker_with(&nats, dir, "w1", 1, &ranges);
    let w2 = worker_with(&nats, dir, "w2", 1, &ranges);
    let (_api, a) = serve(&nats, dir, "api");
    let rt = tokio::runtime::Runtime::new().unwrap();
    let js = rt.block_on(jetstream(&nats));
    let torus = torus_cloud(dir);
    let logs = || w1.log() + &w2.log();
    let mut job = Command::new(BIN)
        .arg("submit")
        .arg(&torus)
        .args([
            "--server",
            &a,
            "--max-memory-mib",
            "110",
            "--resolution",
            "64",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    wait_until(120, "the route tasks", || {
        logs().contains("task=route range")
    });
    let id = job_ids(&a).pop().unwrap();
    cancel_within(&a, &id, 10);
    wait_until(10, "both workers to be idle", || {
        open_tasks(&w1.log()) == 0 && open_tasks(&w2.log()) == 0
    });
    only_the_input_left(&rt, &js, &id);
    let kv = rt.block_on(js.get_key_value("rbfsurf-jobs")).unwrap();
    let prep = rt.block_on(kv.get(format!("prep.{id}"))).unwrap();
    assert!(prep.is_none(), "the prepare state is removed");
    let _ = job.wait();
}
