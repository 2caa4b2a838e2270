//! The distributed executor against a real `nats-server -js` (features `cli`, `server`, `nats`):
//! each test starts its own server on a free loopback port with its own store directory, API
//! nodes (`serve --nats`) and workers as child processes of the built binary, and compares the
//! distributed results with local runs of `rbfsurf reconstruct` on the same input.
//!
//! Skipped with a message when `nats-server` is missing, except under CI=true (then it fails).

mod harness;
mod lifecycle;
mod spread;

use harness::*;
use std::path::Path;

/// A budget that sends the 30,000-point torus out of core (32 blocks of ~1,000 points).
const OUT_OF_CORE_MIB: &str = "110";

/// Mesh files decoded: the same triangles over the same vertex positions, bit for bit; and the
/// files themselves byte for byte (the plan does not depend on the executor's concurrency).
pub(crate) fn assert_same_mesh(a: &Path, b: &Path) {
    let ma = rbfsurf::io::read_mesh(a).unwrap();
    let mb = rbfsurf::io::read_mesh(b).unwrap();
    assert_eq!(ma.triangles.len(), mb.triangles.len(), "{a:?} vs {b:?}");
    assert_eq!(ma.triangles, mb.triangles, "{a:?} vs {b:?}");
    assert_eq!(ma.vertices, mb.vertices, "{a:?} vs {b:?}");
    let (fa, fb) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    assert!(fa == fb, "{a:?} and {b:?} differ as files");
}

/// The torus, its local out-of-core run (mesh, report) under `dir`.
fn torus_and_local_run(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let cloud = torus_cloud(dir);
    let local = dir.join("local.glb");
    rbfsurf(&[
        "reconstruct",
        cloud.to_str().unwrap(),
        "-o",
        local.to_str().unwrap(),
        "--report",
        dir.join("local.json").to_str().unwrap(),
        "--max-memory-mib",
        OUT_OF_CORE_MIB,
        "--resolution",
        "64",
    ]);
    let rep = report(&dir.join("local.json"));
    let blocks = rep["blocks"].as_array().map_or(0, |b| b.len());
    assert!(
        blocks >= 4,
        "the local run should go out of core in blocks: {blocks}"
    );
    (cloud, local)
}

pub(crate) fn workers_of(rep: &serde_json::Value) -> std::collections::BTreeSet<String> {
    (rep["blocks"].as_array().unwrap().iter())
        .map(|b| b["worker"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn distributed_jobs_equal_local_runs_and_outlive_their_api_node() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let _w1 = worker(&nats, dir, "w1", 1);
    let _w2 = worker(&nats, dir, "w2", 1);
    let (mut api_a, a) = serve(&nats, dir, "api-a");
    let (cloud, local) = torus_and_local_run(dir);

    // Out of core: the task graph on two workers gives the local run's mesh.
    let (out, rep_path) = (dir.join("dist.glb"), dir.join("dist.json"));
    let job = submit(
        &a,
        &cloud,
        &out,
        &rep_path,
        &["--max-memory-mib", OUT_OF_CORE_MIB, "--resolution", "64"],
    );
    finish_submit(job);
    assert_same_mesh(&out, &local);
    let (rep, lrep) = (report(&rep_path), report(&dir.join("local.json")));
    assert_eq!(rep["mesh"], lrep["mesh"]);
    assert_eq!(rep["mesh"]["genus"], 1);
    assert_eq!(
        rep["blocks"].as_array().unwrap().len(),
        lrep["blocks"].as_array().unwrap().len()
    );
    // Both workers took part (the one that runs prepare is busy when the block tasks appear, so
    // the other fits at least the first; on an idle machine it may fit them all, so the blocks
    // alone do not always name both).
    let log = std::fs::read_to_string(dir.join("w1.log")).unwrap()
        + &std::fs::read_to_string(dir.join("w2.log")).unwrap();
    let ran: std::collections::BTreeSet<&str> = (log.lines())
        .filter(|l| l.contains("task started"))
        .filter_map(|l| l.split("worker=").nth(1))
        .filter_map(|w| w.split_whitespace().next())
        .collect();
    assert_eq!(ran.len(), 2, "the job's tasks ran on {ran:?}");
    let workers = workers_of(&rep);
    assert!(!workers.is_empty());
    for w in &workers {
        assert!(
            ran.contains(w.as_str()),
            "worker {w} printed its id: {ran:?}"
        );
    }

    // In memory: one whole-job task.
    let small = dir.join("sphere.ply");
    rbfsurf(&[
        "generate",
        "sphere",
        "--points",
        "3000",
        "-o",
        small.to_str().unwrap(),
    ]);
    let small_local = dir.join("small-local.glb");
    rbfsurf(&[
        "reconstruct",
        small.to_str().unwrap(),
        "-o",
        small_local.to_str().unwrap(),
    ]);
    let (small_out, small_rep) = (dir.join("small.glb"), dir.join("small.json"));
    finish_submit(submit(&a, &small, &small_out, &small_rep, &[]));
    assert_same_mesh(&small_out, &small_local);
    assert_eq!(report(&small_rep)["mesh"]["watertight"], true);

    // A new API node with an empty data directory lists both jobs and serves their results.
    let ids = job_ids(&a);
    assert_eq!(ids.len(), 2, "{ids:?}");
    api_a.kill();
    let (_api_b, b) = serve(&nats, dir, "api-b");
    wait_until(30, "the new node to learn the jobs", || {
        job_ids(&b).len() == 2
    });
    for id in &ids {
        wait_until(30, "the job to show as succeeded", || {
            get_json(&b, &format!("/v1/reconstructions/{id}"))["status"] == "succeeded"
        });
    }
    let dist_id = ids
        .iter()
        .find(|id| {
            let (_, r) = get(&b, &format!("/v1/reconstructions/{id}/report"));
            serde_json::from_slice::<serde_json::Value>(&r).unwrap()["blocks"]
                .as_array()
                .is_some_and(|b| !b.is_empty())
        })
        .unwrap();
    let (status, glb) = get(&b, &format!("/v1/reconstructions/{dist_id}/mesh.glb"));
    assert_eq!(status, 200);
    assert_eq!(
        glb,
        std::fs::read(&out).unwrap(),
        "the same GLB from the new node"
    );
}

/// Lines of a worker log that start or finish a task of `kind`.
pub(crate) fn count(log: &str, what: &str, kind: &str) -> usize {
    log.lines()
        .filter(|l| l.contains(what) && l.contains(&format!("task={kind}")))
        .count()
}

#[test]
fn a_killed_worker_and_a_restarted_nats_server_lose_no_job() {
    let Some((tmp, mut nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let mut w1 = worker(&nats, dir, "w1", 1);
    let mut w2 = worker(&nats, dir, "w2", 1);
    let (_api, a) = serve(&nats, dir, "api");
    let (cloud, local) = torus_and_local_run(dir);
    let (out, rep_path) = (dir.join("dist.glb"), dir.join("dist.json"));
    let job = submit(
        &a,
        &cloud,
        &out,
        &rep_path,
        &["--max-memory-mib", OUT_OF_CORE_MIB, "--resolution", "64"],
    );

    // kill -9 the worker that took the start task (reading and preparing take seconds).
    let mut victim = None;
    wait_until(60, "a worker to start the job", || {
        for (k, w) in [(1, &w1), (2, &w2)] {
            let log = w.log();
            if count(&log, "task started", "start") > count(&log, "task finished", "start") {
                victim = Some(k);
                return true;
            }
        }
        false
    });
    if victim == Some(1) {
        w1.kill();
    } else {
        w2.kill();
    }
    let w3 = worker(&nats, dir, "w3", 1);

    // Restart the server once the region phase has begun.
    let logs = || w1.log() + &w2.log() + &w3.log();
    wait_until(180, "the region phase", || logs().contains("task=region"));
    nats.down();
    std::thread::sleep(std::time::Duration::from_secs(2));
    nats.up();

    finish_submit(job);
    assert_same_mesh(&out, &local);
    let all = logs();
    assert!(
        all.lines().any(|l| l.contains("task started")
            && l.contains("task=start")
            && l.contains("delivery=2")),
        "the killed worker's start task was delivered again:\n{all}"
    );
    let rep = report(&rep_path);
    assert_eq!(rep["mesh"]["watertight"], true);
    assert!(workers_of(&rep).len() >= 2, "{:?}", workers_of(&rep));
}

/// Nodes that start together on a fresh server race to create the task stream, the job bucket,
/// the object store and the workers' consumer: every one must start (the losers of a race find
/// what the winner created).
#[test]
fn api_nodes_and_workers_starting_together_all_start() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let nats = &nats;
    let nodes = std::thread::scope(|s| {
        let apis: Vec<_> = (0..4)
            .map(|i| s.spawn(move || serve(nats, dir, &format!("api-{i}"))))
            .collect();
        let workers: Vec<_> = (0..3)
            .map(|i| s.spawn(move || worker(nats, dir, &format!("w{i}"), 1)))
            .collect();
        let apis: Vec<_> = apis.into_iter().map(|h| h.join().unwrap()).collect();
        let workers: Vec<_> = workers.into_iter().map(|h| h.join().unwrap()).collect();
        (apis, workers)
    });
    for (_, base) in &nodes.0 {
        let (status, _) = get(base, "/v1/reconstructions");
        assert_eq!(status, 200, "{base}");
    }
    for w in &nodes.1 {
        wait_until(30, "the worker to wait for tasks", || {
            w.log().contains("waiting for tasks")
        });
    }
}

/// Over its budget, prepared by byte ranges over two workers (`--range-mib 0.125`: 9 ranges of
/// the 1.1 MB PLY): every pass and clean-up task is its own task on the work queue, both
/// workers take them, and the GLB is the local out-of-core run's byte for byte.
#[test]
fn an_out_of_core_job_prepared_by_ranges_over_the_workers_equals_the_local_run() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let ranges = ["--range-mib", "0.125"];
    let w1 = worker_with(&nats, dir, "w1", 1, &ranges);
    let w2 = worker_with(&nats, dir, "w2", 1, &ranges);
    let (_api, a) = serve(&nats, dir, "api");
    let (cloud, local) = torus_and_local_run(dir);
    let (out, rep_path) = (dir.join("dist.glb"), dir.join("dist.json"));
    let job = submit(
        &a,
        &cloud,
        &out,
        &rep_path,
        &["--max-memory-mib", OUT_OF_CORE_MIB, "--resolution", "64"],
    );
    finish_submit(job);
    assert_same_mesh(&out, &local);
    let rep = report(&rep_path);
    let tasks = rep["tasks"].as_array().unwrap();
    let count = |p: &str| {
        (tasks.iter())
            .filter(|t| t["task"].as_str().unwrap().starts_with(p))
            .count()
    };
    assert_eq!(
        (
            count("survey range "),
            count("sample range "),
            count("route range ")
        ),
        (9, 9, 9)
    );
    assert_eq!(count("clean-up "), rep["blocks"].as_array().unwrap().len());
    let logs = w1.log() + &w2.log();
    assert!(logs.contains("prepare by byte ranges over the workers"));
    for kind in ["survey range", "route range", "clean-up"] {
        let on = [&w1, &w2]
            .iter()
            .filter(|w| w.log().contains(&format!("task={kind}")))
            .count();
        assert!(on >= 1, "{kind} tasks ran");
    }
    // The start task read only the input's first segment: no pass ran in it.
    assert!(count("prepare") == 1 && !tasks.iter().any(|t| t["task"] == "route"));
}
