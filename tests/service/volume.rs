//! Volume modelling through the command line and the HTTP API: `--save-field`, `field info`,
//! `csg`, `voxelize`, `morph` (one-line errors, no output file on failure), `GET …/field`,
//! `POST /v1/compositions` and `POST /v1/morphs`.

use crate::server_common::{get, post, sphere_xyz, start, wait_terminal};
use axum::http::StatusCode;
use std::path::Path;
use std::process::Command;

fn rbfsurf(dir: &Path, args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_rbfsurf"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn the_command_line_saves_combines_morphs_and_voxelizes_fields() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("s.xyz"), sphere_xyz(1500, 1)).unwrap();
    let (code, _, err) = rbfsurf(
        d,
        &[
            "reconstruct",
            "s.xyz",
            "-o",
            "s.glb",
            "-q",
            "--save-field",
            "s.field",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = rbfsurf(d, &["field", "info", "s.field"]);
    assert_eq!(code, 0, "{err}");
    let info: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(info["format_version"], 1);
    assert_eq!(info["points"], 1500);
    // A composite, with its report.
    let (code, out, err) = rbfsurf(
        d,
        &[
            "csg",
            "difference(s.field, sphere(0.5, 0.5, 0.9, 0.2))",
            "-o",
            "c.glb",
            "--report",
            "c.json",
            "-q",
            "--resolution",
            "128",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("watertight true"), "{out}");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("c.json")).unwrap()).unwrap();
    assert_eq!(r["mesh"]["components"], 1);
    let (active, total) = (
        r["blocks_active"].as_u64().unwrap(),
        r["blocks_total"].as_u64().unwrap(),
    );
    assert!(active < total, "{active} of {total} blocks evaluated");
    // Bad input: one line, non-zero exit, no output.
    let corrupt = {
        let mut b = std::fs::read(d.join("s.field")).unwrap();
        let n = b.len();
        b[n / 2] ^= 0x40;
        b
    };
    std::fs::write(d.join("bad.field"), corrupt).unwrap();
    for (expr, needle) in [
        ("onion(s.field, s.field)", "unknown operation 'onion'"),
        ("union(s.field)", "union at column 1 takes"),
        (
            "union(s.field, missing.field)",
            "missing.field: cannot read",
        ),
        (
            "union(s.field, bad.field)",
            "bad.field: not a valid rbfsurf field file",
        ),
        (
            "intersection(sphere(0,0,0,1), sphere(5,0,0,1))",
            "the result is empty",
        ),
    ] {
        let (code, _, err) = rbfsurf(d, &["csg", expr, "-o", "x.glb", "-q"]);
        assert_ne!(code, 0, "{expr}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(needle), "{expr}: {err}");
        assert!(!d.join("x.glb").exists(), "{expr} left an output file");
    }
    // Volume data.
    let (code, _, err) = rbfsurf(
        d,
        &["voxelize", "s.field", "--resolution", "24", "-o", "s.vti"],
    );
    assert_eq!(code, 0, "{err}");
    let vti = std::fs::read(d.join("s.vti")).unwrap();
    assert!(vti.starts_with(b"<?xml") && vti.windows(9).any(|w| w == b"ImageData"));
    let (code, _, _) = rbfsurf(
        d,
        &["voxelize", "s.field", "--resolution", "24", "-o", "s.raw"],
    );
    assert_ne!(code, 0);
    assert!(!d.join("s.raw").exists());
    // A morph to a torus primitive with an obstacle no frame enters.
    let (code, out, err) = rbfsurf(
        d,
        &[
            "morph",
            "s.field",
            "torus(0,0,0,1,0.3)",
            "--frames",
            "4",
            "-o",
            "m",
            "--resolution",
            "40",
            "--obstacle",
            "box(-1,-1,-1,1,1,0.3)",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("4 frames"), "{out}");
    for f in ["frame_000.glb", "frame_003.glb", "morph.glb", "report.json"] {
        assert!(d.join("m").join(f).exists(), "{f}");
    }
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("m/report.json")).unwrap()).unwrap();
    assert_eq!(r["frames"].as_array().unwrap().len(), 4);
    for k in 0..4 {
        let mesh = rbfsurf::io::read_mesh(&d.join(format!("m/frame_{k:03}.glb"))).unwrap();
        let z_min = mesh
            .vertices
            .iter()
            .map(|v| v[2])
            .fold(f64::INFINITY, f64::min);
        // The obstacle covers z < 0.3 of the sphere's box [0.1, 0.9]³: nothing below it (up to the
        // root finding's tolerance at the crease: a tenth of a cell, 2·10⁻³; measured up to 1.4·10⁻³
        // on the anisotropically aligned torus).
        assert!(
            z_min > 0.3 - 2e-3,
            "frame {k} enters the obstacle: z = {z_min}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fields_compositions_and_morphs_over_http() {
    let s = start(|_| {});
    let a = post(
        &s.app,
        "/v1/reconstructions?wait=60",
        "text/plain",
        sphere_xyz(1500, 2),
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    let id = a.json()["id"].as_str().unwrap().to_string();
    let f = get(&s.app, &format!("/v1/reconstructions/{id}/field")).await;
    assert_eq!(f.status, StatusCode::OK);
    let model = rbfsurf::frep::format::decode(&f.body, "<http>").unwrap();
    assert_eq!(model.points.len(), 1500);
    // Compose the job with a primitive.
    let body = serde_json::json!({"expression": format!("union({id}, sphere(0.5, 0.5, 1.0, 0.2))"), "resolution": 48});
    let c = post(
        &s.app,
        "/v1/compositions",
        "application/json",
        body.to_string(),
    )
    .await;
    assert_eq!(
        c.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&c.body)
    );
    let cid = c.json()["id"].as_str().unwrap().to_string();
    let v = wait_terminal(&s.app, &cid, 60).await;
    assert_eq!(v["status"], "succeeded", "{v}");
    assert_eq!(v["report"]["mesh"]["watertight"], true);
    let glb = get(&s.app, &format!("/v1/reconstructions/{cid}/mesh.glb")).await;
    assert_eq!(glb.status, StatusCode::OK);
    // A morph from the job to a torus.
    let body =
        serde_json::json!({"a": id, "b": "torus(0,0,0,1,0.3)", "frames": 3, "resolution": 32});
    let m = post(&s.app, "/v1/morphs", "application/json", body.to_string()).await;
    assert_eq!(
        m.status,
        StatusCode::ACCEPTED,
        "{}",
        String::from_utf8_lossy(&m.body)
    );
    let mid = m.json()["id"].as_str().unwrap().to_string();
    let v = wait_terminal(&s.app, &mid, 60).await;
    assert_eq!(v["status"], "succeeded", "{v}");
    assert_eq!(v["report"]["frames"].as_array().unwrap().len(), 3);
    // Refusals: server paths, unknown jobs, bad operations, unknown fields.
    for (body, status) in [
        (
            serde_json::json!({"expression": "union(/etc/passwd, sphere(0,0,0,1))"}),
            StatusCode::UNPROCESSABLE_ENTITY,
        ),
        (
            serde_json::json!({"expression": "union(00000000-0000-4000-8000-000000000000, sphere(0,0,0,1))"}),
            StatusCode::NOT_FOUND,
        ),
        (
            serde_json::json!({"expression": format!("onion({id}, {id})")}),
            StatusCode::UNPROCESSABLE_ENTITY,
        ),
        (
            serde_json::json!({"expression": format!("union({id}, {cid})")}),
            StatusCode::UNPROCESSABLE_ENTITY,
        ),
        (
            serde_json::json!({"expression": "sphere(0,0,0,1)", "resolution": 100000}),
            StatusCode::BAD_REQUEST,
        ),
        (
            serde_json::json!({"expr": "sphere(0,0,0,1)"}),
            StatusCode::BAD_REQUEST,
        ),
        (
            serde_json::json!({"expression": "x".repeat(70_000)}),
            StatusCode::PAYLOAD_TOO_LARGE,
        ),
    ] {
        let a = post(
            &s.app,
            "/v1/compositions",
            "application/json",
            body.to_string(),
        )
        .await;
        a.expect_error(status);
    }
}
