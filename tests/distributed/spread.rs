//! A job within its memory budget split over idle workers (`rbfsurf worker --spread-points`):
//! the same mesh as the local out-of-core run at the same budget, the task timeline in the
//! report, and a worker killed mid-block survived.

use crate::harness::*;
use crate::{assert_same_mesh, count, workers_of};
use std::path::{Path, PathBuf};

/// A budget the 30,000-point torus fits in memory (estimate 112 MiB) whose out-of-core plan has
/// several blocks (~7,300 core points each).
const WITHIN_MIB: &str = "128";
/// The threshold and byte ranges of 128 KiB: the torus's 1.1 MB PLY is prepared in 9 ranges.
const SPREAD_BY_RANGES: [&str; 4] = ["--spread-points", "10000", "--range-mib", "0.125"];
const JOB: [&str; 4] = ["--max-memory-mib", WITHIN_MIB, "--resolution", "64"];

/// The torus and its local run through the task graph at the same budget (`--out-of-core`).
fn torus_and_local_graph_run(dir: &Path) -> (PathBuf, PathBuf) {
    let cloud = torus_cloud(dir);
    let local = dir.join("local-graph.glb");
    let mut args = vec![
        "reconstruct",
        cloud.to_str().unwrap(),
        "-o",
        local.to_str().unwrap(),
        "--report",
    ];
    let rep = dir.join("local-graph.json");
    args.push(rep.to_str().unwrap());
    args.extend(JOB);
    args.push("--out-of-core");
    rbfsurf(&args);
    let blocks = report(&rep)["blocks"].as_array().map_or(0, |b| b.len());
    assert!(blocks >= 3, "the local graph run has {blocks} blocks");
    (cloud, local)
}

/// The report's `tasks[]` cover prepare, every block and region, and merge, each interval
/// ordered and named by a worker; the critical path is prepare → block → region → merge.
fn assert_timeline(rep: &serde_json::Value) {
    let tasks = rep["tasks"].as_array().expect("tasks[]");
    let named = |p: &str| {
        (tasks.iter())
            .filter(|t| t["task"].as_str().unwrap().starts_with(p))
            .count()
    };
    assert_eq!(named("prepare"), 1);
    assert_eq!(named("merge"), 1);
    assert_eq!(named("block "), rep["blocks"].as_array().unwrap().len());
    assert!(named("region ") >= 1);
    for t in tasks {
        let (s, e) = (
            t["start_ms"].as_u64().unwrap(),
            t["end_ms"].as_u64().unwrap(),
        );
        assert!(s <= e && !t["worker"].as_str().unwrap().is_empty(), "{t}");
        let secs = t["seconds"].as_f64().unwrap();
        assert!((secs - (e - s) as f64 / 1000.0).abs() < 1e-9, "{t}");
    }
    let path = &rep["critical_path"];
    let chain: Vec<&str> = (path["tasks"].as_array().unwrap().iter())
        .map(|t| t.as_str().unwrap())
        .collect();
    let n = chain.len();
    assert!(chain[n - 1] == "merge", "{path}");
    assert!(chain[n - 3].starts_with("block ") && chain[n - 2].starts_with("region "));
    if named("clean-up ") > 0 {
        // Prepare spread over the workers: its phases, each after the one before.
        let first = [
            "survey range ",
            "number ranges",
            "sample range ",
            "plan blocks",
        ];
        let then = ["route range ", "estimates ", "clean-up ", "complete plan"];
        assert_eq!(n, 11, "{path}");
        for (c, p) in chain.iter().zip(first.iter().chain(&then)) {
            assert!(c.starts_with(p), "{path}");
        }
        assert_eq!(named("clean-up "), rep["blocks"].as_array().unwrap().len());
    } else {
        assert_eq!(n, 4, "{path}");
        assert_eq!(chain[0], "prepare", "{path}");
    }
    let (cp, wall) = (
        path["seconds"].as_f64().unwrap(),
        path["wall_seconds"].as_f64().unwrap(),
    );
    assert!(cp > 0.0 && cp <= wall + 1e-3, "{path}");
}

/// The workers prepare by byte ranges, the local run reads the input whole: the same GLB.
#[test]
fn a_large_job_within_its_budget_spreads_over_idle_workers_with_the_local_graph_mesh() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let w1 = worker_with(&nats, dir, "w1", 1, &SPREAD_BY_RANGES);
    let (_api, a) = serve(&nats, dir, "api");
    let (cloud, local) = torus_and_local_graph_run(dir);
    wait_until(30, "w1 to wait for tasks", || {
        w1.log().contains("waiting for tasks")
    });

    // One worker: no other is idle, the job runs whole (no blocks).
    let (alone, alone_rep) = (dir.join("alone.glb"), dir.join("alone.json"));
    finish_submit(submit(&a, &cloud, &alone, &alone_rep, &JOB));
    let rep = report(&alone_rep);
    assert!(rep.get("blocks").is_none() && rep.get("tasks").is_none());
    assert!(!w1.log().contains("splitting the job"));

    // A second, idle worker: the job is split and equals the local graph run bit for bit.
    let w2 = worker_with(&nats, dir, "w2", 1, &SPREAD_BY_RANGES);
    wait_until(30, "w2 to wait for tasks", || {
        w2.log().contains("waiting for tasks")
    });
    std::thread::sleep(std::time::Duration::from_millis(500));
    let (out, rep_path) = (dir.join("spread.glb"), dir.join("spread.json"));
    finish_submit(submit(&a, &cloud, &out, &rep_path, &JOB));
    let logs = w1.log() + &w2.log();
    assert!(logs.contains("splitting the job into block tasks"));
    assert!(
        logs.contains("prepare by byte ranges over the workers"),
        "{logs}"
    );
    assert_same_mesh(&out, &local);
    let (rep, lrep) = (report(&rep_path), report(&dir.join("local-graph.json")));
    assert_eq!(rep["mesh"], lrep["mesh"]);
    assert_eq!(rep["mesh"]["watertight"], true);
    assert_eq!(rep["mesh"]["genus"], 1);
    assert_timeline(&rep);
    let local_tasks = lrep["tasks"].as_array().unwrap();
    assert!(
        local_tasks.iter().any(|t| t["task"] == "route"),
        "read whole"
    );
    let tasks = rep["tasks"].as_array().unwrap();
    for pass in ["survey range ", "sample range ", "route range "] {
        let n = (tasks.iter())
            .filter(|t| t["task"].as_str().unwrap().starts_with(pass))
            .count();
        assert_eq!(n, 9, "{pass}tasks");
    }
    // One clean-up task per block, and the passes' tasks on both workers.
    assert!(tasks.iter().any(|t| t["task"] == "clean-up 0"));
    for pass in ["survey range ", "route range ", "clean-up "] {
        let on: std::collections::BTreeSet<&str> = (tasks.iter())
            .filter(|t| t["task"].as_str().unwrap().starts_with(pass))
            .map(|t| t["worker"].as_str().unwrap())
            .collect();
        assert_eq!(on.len(), 2, "{pass}tasks ran on {on:?}");
    }
    let ran: std::collections::BTreeSet<&str> = (rep["tasks"].as_array().unwrap().iter())
        .map(|t| t["worker"].as_str().unwrap())
        .collect();
    assert_eq!(ran.len(), 2, "both workers ran tasks: {ran:?}");
}

#[test]
fn a_spread_job_survives_a_worker_killed_mid_block() {
    let Some((tmp, nats)) = private_nats() else {
        return;
    };
    let dir = tmp.path();
    let mut ws: Vec<Proc> = (1..=3)
        .map(|i| worker_with(&nats, dir, &format!("w{i}"), 1, &SPREAD_BY_RANGES))
        .collect();
    let (_api, a) = serve(&nats, dir, "api");
    let (cloud, local) = torus_and_local_graph_run(dir);
    for w in &ws {
        wait_until(30, "the workers to wait for tasks", || {
            w.log().contains("waiting for tasks")
        });
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    let (out, rep_path) = (dir.join("spread.glb"), dir.join("spread.json"));
    let job = submit(&a, &cloud, &out, &rep_path, &JOB);

    // kill -9 a worker while it fits a block.
    let mut victim = None;
    wait_until(120, "a worker in the middle of a block", || {
        victim = (ws.iter()).position(|w| {
            let log = w.log();
            count(&log, "task started", "block") > count(&log, "task finished", "block")
        });
        victim.is_some()
    });
    let victim = victim.unwrap();
    ws[victim].kill();

    finish_submit(job);
    assert_same_mesh(&out, &local);
    let all: String = ws.iter().map(|w| w.log()).collect();
    assert!(
        all.lines().any(|l| l.contains("task started")
            && l.contains("task=block")
            && l.contains("delivery=2")),
        "the killed worker's block was delivered again:\n{all}"
    );
    let rep = report(&rep_path);
    assert_eq!(rep["mesh"]["watertight"], true);
    assert_timeline(&rep);
    assert!(workers_of(&rep).len() >= 2, "{:?}", workers_of(&rep));
}
