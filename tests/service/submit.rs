//! `rbfsurf submit` against a real listener: success writes the mesh and report (exit 0); an
//! unreconstructable file, a bad parameter, a missing token and an unreachable server exit non-zero.

use crate::server_common;

use server_common::{sphere_xyz, start_on};
use std::process::Command;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn submit_exits_zero_only_on_success() {
    let dir = tempfile::tempdir().unwrap();
    let state = start_on(&dir.path().join("jobs"), |c| c.token = Some("tok".into()));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let (stop, rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(rbfsurf::server::serve_on(listener, state, async move {
        let _ = rx.await;
    }));
    let cloud = dir.path().join("sphere.xyz");
    std::fs::write(&cloud, sphere_xyz(500, 21)).unwrap();
    let line = dir.path().join("line.xyz");
    std::fs::write(&line, "0 0 0\n1 1 1\n2 2 2\n3 3 3\n4 4 4\n").unwrap();
    let out = dir.path().join("mesh.ply");
    let report = dir.path().join("report.json");
    let run = move |args: Vec<String>| {
        Command::new(env!("CARGO_BIN_EXE_rbfsurf"))
            .arg("submit")
            .args(args)
            .output()
            .unwrap()
    };
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let (c, u, o, r) = (
        cloud.display().to_string(),
        url.clone(),
        out.display().to_string(),
        report.display().to_string(),
    );
    let ok = tokio::task::spawn_blocking({
        let a = s(&[
            &c,
            "--server",
            &u,
            "--token",
            "tok",
            "-o",
            &o,
            "--report",
            &r,
            "--require-watertight",
            "--resolution",
            "24",
        ]);
        move || run(a)
    })
    .await
    .unwrap();
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let mesh = rbfsurf::io::read_mesh(&out).unwrap();
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    // The compact GLB drops the slivers its 16-bit grid merges (at most 0.5 %, docs/formats.md).
    let reported = rep["mesh"]["triangles"].as_u64().unwrap() as usize;
    let file = mesh.triangles.len();
    assert!(
        file <= reported && reported - file <= reported / 200,
        "{file} vs {reported}"
    );
    let l = line.display().to_string();
    for (args, expect) in [
        (
            s(&[&l, "--server", &u, "--token", "tok", "--wait"]),
            "straight line",
        ),
        (s(&[&c, "--server", &u, "--wait"]), "401"),
        (
            s(&[&c, "--server", &u, "--token", "tok", "--kernel", "gauss"]),
            "gauss",
        ),
        (
            s(&[&c, "--server", "http://127.0.0.1:1", "--token", "tok"]),
            "cannot connect",
        ),
    ] {
        let res = tokio::task::spawn_blocking(move || run(args))
            .await
            .unwrap();
        let err = String::from_utf8_lossy(&res.stderr).to_string();
        assert!(!res.status.success(), "{expect}: exited 0");
        assert!(err.contains(expect), "{expect}: {err}");
    }
    stop.send(()).unwrap();
    server.await.unwrap().unwrap();
}
