//! The HTTP API in-process (router + tower `oneshot`): results, every error status with its JSON
//! body, hostile inputs, limits enforced before reading, SSE progress, cancel, time limits,
//! restart recovery, expiry, and the OpenAPI document against proto/openapi.json.

use crate::server_common;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use futures_util::stream;
use server_common::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

const SMALL: &str = "resolution=24";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wait_returns_the_finished_job_and_every_download() {
    let s = start(|_| {});
    let a = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}&wait=60"),
        "text/plain",
        sphere_xyz(1000, 1),
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    let job = a.json();
    assert_eq!(job["status"], "succeeded");
    assert_eq!(job["input"]["points"], 1000);
    assert_eq!(job["report"]["params"]["resolution"], 24);
    assert_eq!(job["report"]["mesh"]["watertight"], true);
    let id = job["id"].as_str().unwrap();
    let glb = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.glb")).await;
    assert_eq!(glb.status, StatusCode::OK);
    assert_eq!(glb.headers["content-type"], "model/gltf-binary");
    let mesh = rbfsurf::io::decode_glb(&glb.body).unwrap();
    // The compact GLB merges vertices on its 16-bit grid and drops the slivers between them
    // (docs/formats.md: 0.08–0.14 % of the triangles on the shared scans).
    let (file, job_tri) = (
        mesh.triangles.len() as u64,
        job["triangles"].as_u64().unwrap(),
    );
    assert!(
        file <= job_tri && job_tri - file <= job_tri / 200,
        "{file} vs {job_tri}"
    );
    // Vertices lie near the sampled sphere (centre 0.5, radius 0.4), so the file is the real result.
    let sphere = rbfsurf::geometry::synthetic::Shape::by_name("sphere").unwrap();
    let mut dev: Vec<f64> = mesh
        .vertices
        .iter()
        .map(|v| sphere.signed_distance(v).abs())
        .collect();
    dev.sort_by(f64::total_cmp);
    let (median, p99) = (dev[dev.len() / 2], dev[dev.len() * 99 / 100]);
    assert!(
        median < 0.004 && p99 < 0.02,
        "off the sphere: median {median}, p99 {p99}, max {}",
        dev[dev.len() - 1]
    );
    for ext in ["ply", "obj"] {
        let m = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.{ext}")).await;
        assert_eq!(m.status, StatusCode::OK, "{ext}");
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(format!("m.{ext}"));
        std::fs::write(&p, &m.body).unwrap();
        assert_eq!(
            rbfsurf::io::read_mesh(&p).unwrap().triangles.len(),
            mesh.triangles.len()
        );
    }
    let rep = get(&s.app, &format!("/v1/reconstructions/{id}/report")).await;
    assert_eq!(rep.status, StatusCode::OK);
    assert_eq!(rep.json()["mesh"], job["report"]["mesh"]);
    let list = get(&s.app, "/v1/reconstructions").await.json();
    assert_eq!(list.as_array().unwrap().len(), 1);
    assert_eq!(list[0]["id"], id);
    for f in [
        "input.xyz",
        "params.json",
        "status.json",
        "report.json",
        "mesh.glb",
    ] {
        assert!(s.dir.path().join(id).join(f).is_file(), "{f} stored");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn las_laz_and_e57_uploads_give_coloured_georeferenced_meshes() {
    use crate::scanner_files::{E57Coords, LasSpec, Scan, e57_bytes, las_bytes};
    let s = start(|_| {});
    let centre = [500_000.0, 4_100_000.0, 300.0];
    let shape = rbfsurf::geometry::synthetic::Shape::Sphere {
        center: centre,
        radius: 10.0,
    };
    let scan = Scan::on_grid(&shape.sample(1500, 2).points, centre, centre, 10.0);
    let mut spec = LasSpec::new((1, 2), 3, false);
    spec.epsg = Some(32633);
    let las = las_bytes(&scan, &spec);
    spec.laz = true;
    let laz = las_bytes(&scan, &spec);
    let e57 = e57_bytes(&scan, 2, E57Coords::Cartesian, Some("EPSG:32633"));
    // LAS by its media type; LAZ and E57 as octet streams, recognised by their signatures.
    for (name, ctype, body) in [
        ("las", "application/vnd.las", las),
        ("laz", "application/octet-stream", laz),
        ("e57", "application/octet-stream", e57),
    ] {
        let uri = format!("/v1/reconstructions?{SMALL}&wait=60");
        let a = post(&s.app, &uri, ctype, body).await;
        assert_eq!(
            a.status,
            StatusCode::OK,
            "{name}: {}",
            String::from_utf8_lossy(&a.body)
        );
        let job = a.json();
        assert_eq!(job["status"], "succeeded", "{name}: {job}");
        assert_eq!(job["input"]["points"], 1500, "{name}");
        let attrs = &job["report"]["attributes"];
        assert_eq!(attrs["color"], "rgb", "{name}: {attrs}");
        assert_eq!(attrs["crs"], "EPSG:32633", "{name}");
        let id = job["id"].as_str().unwrap();
        let glb = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.glb")).await;
        let mesh = rbfsurf::io::decode_glb(&glb.body).unwrap();
        assert_eq!(mesh.colors.len(), mesh.vertices.len(), "{name}");
        assert_eq!(
            rbfsurf::io::glb_crs(&glb.body).as_deref(),
            Some("EPSG:32633")
        );
        // Vertices at UTM coordinates, within centimetres of the sphere.
        let worst = (mesh.vertices.iter())
            .map(|v| (shape.signed_distance(v)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.5, "{name}: {worst} m off the sphere");
        let ply = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.ply")).await;
        let head = String::from_utf8_lossy(&ply.body[..600]).into_owned();
        for needle in [
            "comment crs EPSG:32633",
            "property double x",
            "property uchar red",
        ] {
            assert!(head.contains(needle), "{name}: {needle}: {head}");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn multipart_upload_takes_file_and_parameter_fields() {
    let s = start(|_| {});
    let b = "XbOuNdArY";
    let mut body = Vec::new();
    body.extend_from_slice(
        format!("--{b}\r\nContent-Disposition: form-data; name=\"resolution\"\r\n\r\n28\r\n")
            .as_bytes(),
    );
    body.extend_from_slice(
        format!("--{b}\r\nContent-Disposition: form-data; name=\"wait\"\r\n\r\n60\r\n").as_bytes(),
    );
    body.extend_from_slice(format!("--{b}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"cloud.xyz\"\r\nContent-Type: application/octet-stream\r\n\r\n").as_bytes());
    body.extend_from_slice(&sphere_xyz(300, 2));
    body.extend_from_slice(format!("\r\n--{b}--\r\n").as_bytes());
    let a = post(
        &s.app,
        "/v1/reconstructions",
        &format!("multipart/form-data; boundary={b}"),
        body,
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    assert_eq!(a.json()["report"]["params"]["resolution"], 28);
    // A bad field is refused like a bad query parameter.
    let bad = format!(
        "--{b}\r\nContent-Disposition: form-data; name=\"kernel\"\r\n\r\ngauss\r\n--{b}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"c.xyz\"\r\n\r\n0 0 0\r\n--{b}--\r\n"
    );
    let a = post(
        &s.app,
        "/v1/reconstructions",
        &format!("multipart/form-data; boundary={b}"),
        bad,
    )
    .await;
    assert_eq!(a.expect_error(StatusCode::BAD_REQUEST), "bad_parameter");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_parameters_and_media_types_are_json_errors() {
    let s = start(|_| {});
    let cloud = sphere_xyz(100, 3);
    for q in [
        "resolution=2",
        "resolution=abc",
        "resolution=-5",
        "support=0",
        "support=nan",
        "neighbours=1",
        "kernel=gauss",
        "bogus=1",
        "wait=-1",
        "merge-tolerance=1",
        "max-memory-mib=0",
    ] {
        let a = post(
            &s.app,
            &format!("/v1/reconstructions?{q}"),
            "text/plain",
            cloud.clone(),
        )
        .await;
        assert_eq!(
            a.expect_error(StatusCode::BAD_REQUEST),
            "bad_parameter",
            "{q}"
        );
    }
    // A parameter given twice (in the query, or in the query and a multipart field) is one
    // that conflicts with itself.
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=32&resolution=40",
        "text/plain",
        cloud.clone(),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::UNPROCESSABLE_ENTITY),
        "conflicting_parameters"
    );
    for ct in ["image/png", "application/json", "model/gltf-binary"] {
        let a = post(&s.app, "/v1/reconstructions", ct, cloud.clone()).await;
        assert_eq!(
            a.expect_error(StatusCode::UNSUPPORTED_MEDIA_TYPE),
            "unsupported_media_type",
            "{ct}"
        );
    }
    // Binary garbage labelled octet-stream: sniffed, not a point format.
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let garbage: Vec<u8> = (0..4096)
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 24) as u8
        })
        .collect();
    let a = post(
        &s.app,
        "/v1/reconstructions",
        "application/octet-stream",
        garbage.clone(),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::UNSUPPORTED_MEDIA_TYPE),
        "unsupported_media_type"
    );
    // The same garbage claimed to be PLY: a parse error about the data.
    let a = post(&s.app, "/v1/reconstructions", "application/ply", garbage).await;
    assert_eq!(
        a.expect_error(StatusCode::UNPROCESSABLE_ENTITY),
        "invalid_input"
    );
    assert_eq!(s.state.jobs.list().len(), 0, "nothing was queued");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_point_files_are_refused_and_the_server_keeps_working() {
    let s = start(|c| c.max_points = 1000);
    let header = |n: &str| {
        format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
        )
    };
    let cases: Vec<(&str, Vec<u8>, StatusCode, &str)> = vec![
        (
            "absurd count",
            header("99999999999999").into_bytes(),
            StatusCode::PAYLOAD_TOO_LARGE,
            "too_large",
        ),
        (
            "count overflows u64",
            header("999999999999999999999999").into_bytes(),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_input",
        ),
        (
            "truncated binary",
            {
                let mut b = header("500").into_bytes();
                b.extend_from_slice(&[0u8; 100]);
                b
            },
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_input",
        ),
        (
            "all NaN",
            "nan nan nan\nnan 1 2\n1 nan 2\ninf 0 0\n0 -inf 0\n".into(),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unreconstructable",
        ),
        (
            "three points",
            "0 0 0\n1 0 0\n0 1 0\n".into(),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unreconstructable",
        ),
        (
            "collinear",
            (0..50)
                .map(|i| format!("{i} {i} {i}\n"))
                .collect::<String>()
                .into_bytes(),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unreconstructable",
        ),
        (
            "too many points",
            sphere_xyz(1500, 4),
            StatusCode::PAYLOAD_TOO_LARGE,
            "too_large",
        ),
        (
            "empty",
            Vec::new(),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_input",
        ),
        (
            "text soup",
            b"hello world\nthis is not a point file\n".to_vec(),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_input",
        ),
    ];
    for (what, body, status, code) in cases {
        let ct = if body.starts_with(b"ply") {
            "application/ply"
        } else {
            "text/plain"
        };
        // Degenerate clouds parse and are refused by their job (under its time limit), which
        // `wait` answers with the failure's status.
        let a = post(&s.app, "/v1/reconstructions?wait=60", ct, body).await;
        assert_eq!(a.expect_error(status), code, "{what}");
    }
    // NaNs mixed into a good cloud are dropped and counted, not fatal.
    let mut mixed = sphere_xyz(300, 5);
    mixed.extend_from_slice(b"nan 0 0 0 0 1\n0 inf 0 0 0 1\n");
    let a = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}&wait=60"),
        "text/plain",
        mixed,
    )
    .await;
    assert_eq!(
        a.status,
        StatusCode::OK,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    assert_eq!(a.json()["report"]["input"]["dropped_non_finite"], 2);
    assert_eq!(get(&s.app, "/healthz").await.status, StatusCode::OK);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unknown_ids_and_path_tricks_are_404() {
    let s = start(|_| {});
    let unknown = uuid::Uuid::new_v4();
    for path in [
        format!("/v1/reconstructions/{unknown}"),
        format!("/v1/reconstructions/{unknown}/mesh.glb"),
        format!("/v1/reconstructions/{unknown}/report"),
        format!("/v1/reconstructions/{unknown}/events"),
        "/v1/reconstructions/not-a-uuid".into(),
        "/v1/reconstructions/..%2F..%2Fetc%2Fpasswd".into(),
        "/v1/reconstructions/%2e%2e/mesh.glb".into(),
        "/v1/reconstructions/..%5C..%5Cwindows/report".into(),
        format!("/v1/reconstructions/{}/mesh.glb", unknown.simple()).replace('a', "A"),
        "/v1/nothing".into(),
        "/../../etc/passwd".into(),
    ] {
        let a = get(&s.app, &path).await;
        assert_eq!(a.expect_error(StatusCode::NOT_FOUND), "not_found", "{path}");
    }
    let a = delete(&s.app, &format!("/v1/reconstructions/{unknown}")).await;
    assert_eq!(a.expect_error(StatusCode::NOT_FOUND), "not_found");
    let a = send(
        &s.app,
        Request::put("/v1/reconstructions")
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::METHOD_NOT_ALLOWED),
        "method_not_allowed"
    );
    // Stray files in the data directory are never listed or served.
    std::fs::create_dir_all(s.dir.path().join("junk")).unwrap();
    assert_eq!(
        get(&s.app, "/v1/reconstructions")
            .await
            .json()
            .as_array()
            .unwrap()
            .len(),
        0
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn token_guards_mutating_endpoints() {
    let s = start(|c| c.token = Some("s3cret".into()));
    let a = post(
        &s.app,
        "/v1/reconstructions",
        "text/plain",
        sphere_xyz(100, 6),
    )
    .await;
    assert_eq!(a.expect_error(StatusCode::UNAUTHORIZED), "unauthorized");
    assert_eq!(a.headers["www-authenticate"], "Bearer");
    let req = |tok: &str| {
        Request::post(format!("/v1/reconstructions?{SMALL}&wait=60"))
            .header("content-type", "text/plain")
            .header("authorization", format!("Bearer {tok}"))
            .body(Body::from(sphere_xyz(200, 6)))
            .unwrap()
    };
    assert_eq!(
        send(&s.app, req("wrong"))
            .await
            .expect_error(StatusCode::UNAUTHORIZED),
        "unauthorized"
    );
    let ok = send(&s.app, req("s3cret")).await;
    assert_eq!(ok.status, StatusCode::OK);
    let id = ok.json()["id"].as_str().unwrap().to_string();
    // Reads are open; DELETE needs the token.
    assert_eq!(
        get(&s.app, &format!("/v1/reconstructions/{id}"))
            .await
            .status,
        StatusCode::OK
    );
    let a = delete(&s.app, &format!("/v1/reconstructions/{id}")).await;
    assert_eq!(a.expect_error(StatusCode::UNAUTHORIZED), "unauthorized");
    let d = Request::delete(format!("/v1/reconstructions/{id}"))
        .header("authorization", "Bearer s3cret")
        .body(Body::empty())
        .unwrap();
    assert_eq!(send(&s.app, d).await.status, StatusCode::NO_CONTENT);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversized_uploads_get_413_without_the_body_being_read() {
    let s = start(|c| c.max_upload_bytes = 64 << 10);
    // Declared too large: answered from the headers; the body is never polled.
    let polled = Arc::new(AtomicBool::new(false));
    let p = polled.clone();
    let body = Body::from_stream(stream::poll_fn(move |_| {
        p.store(true, Ordering::SeqCst);
        std::task::Poll::Ready(Some(Ok::<_, std::io::Error>(vec![b'1'; 1024])))
    }));
    let req = Request::post("/v1/reconstructions")
        .header("content-type", "text/plain")
        .header("content-length", (1u64 << 40).to_string())
        .body(body)
        .unwrap();
    let a = send(&s.app, req).await;
    assert_eq!(a.expect_error(StatusCode::PAYLOAD_TOO_LARGE), "too_large");
    assert!(!polled.load(Ordering::SeqCst), "body was read");
    // Chunked (no length): reading stops soon after the limit, not at the end of the stream.
    let sent = Arc::new(AtomicUsize::new(0));
    let c = sent.clone();
    let body = Body::from_stream(stream::poll_fn(move |_| {
        c.fetch_add(4096, Ordering::SeqCst);
        std::task::Poll::Ready(Some(Ok::<_, std::io::Error>(b"0 0 0\n".repeat(4096 / 6))))
    }));
    let req = Request::post("/v1/reconstructions")
        .header("content-type", "text/plain")
        .body(body)
        .unwrap();
    let a = send(&s.app, req).await;
    assert_eq!(a.expect_error(StatusCode::PAYLOAD_TOO_LARGE), "too_large");
    // After the answer the refused body is drained for a lingering close, at most twice the
    // limit (the drain runs on its own task): the endless stream is never read to its end.
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    assert!(
        sent.load(Ordering::SeqCst) <= 2 * (64 << 10) + 8192,
        "read {} bytes",
        sent.load(Ordering::SeqCst)
    );
    // Multipart over the limit too.
    let b = "bnd";
    let mut mp = format!(
        "--{b}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"c.xyz\"\r\n\r\n"
    )
    .into_bytes();
    mp.extend(std::iter::repeat_n(b'1', 200 << 10));
    mp.extend_from_slice(format!("\r\n--{b}--\r\n").as_bytes());
    let a = post(
        &s.app,
        "/v1/reconstructions",
        &format!("multipart/form-data; boundary={b}"),
        mp,
    )
    .await;
    assert_eq!(a.expect_error(StatusCode::PAYLOAD_TOO_LARGE), "too_large");
    // An aborted body is a 400, and the server still answers.
    let body = Body::from_stream(stream::iter(vec![
        Ok(b"0 0 0\n1 0 0\n".to_vec()),
        Err(std::io::Error::new(
            std::io::ErrorKind::ConnectionReset,
            "client went away",
        )),
    ]));
    let req = Request::post("/v1/reconstructions")
        .header("content-type", "text/plain")
        .body(body)
        .unwrap();
    assert_eq!(
        send(&s.app, req)
            .await
            .expect_error(StatusCode::BAD_REQUEST),
        "incomplete_body"
    );
    assert_eq!(get(&s.app, "/healthz").await.status, StatusCode::OK);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_queue_is_429_and_shutdown_is_503() {
    let s = start(|c| c.max_queue = 0);
    let a = post(
        &s.app,
        "/v1/reconstructions",
        "text/plain",
        sphere_xyz(100, 7),
    )
    .await;
    assert_eq!(a.expect_error(StatusCode::TOO_MANY_REQUESTS), "queue_full");
    assert!(
        a.headers["retry-after"]
            .to_str()
            .unwrap()
            .parse::<u64>()
            .unwrap()
            > 0
    );
    let jobs = s.state.jobs.clone();
    tokio::task::spawn_blocking(move || jobs.shutdown())
        .await
        .unwrap();
    let a = post(
        &s.app,
        "/v1/reconstructions",
        "text/plain",
        sphere_xyz(100, 7),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::SERVICE_UNAVAILABLE),
        "shutting_down"
    );
    assert!(a.headers.contains_key("retry-after"));
    assert_eq!(
        get(&s.app, "/healthz")
            .await
            .expect_error(StatusCode::SERVICE_UNAVAILABLE),
        "shutting_down"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wait_on_a_job_that_cannot_fit_its_budget_is_422_with_the_job() {
    // Support 2 (the whole cloud) on 3000 points: ~9e6 matrix values, over a 16 MiB budget:
    // refused at submit (the feasibility check), before a job exists.
    let s = start(|_| {});
    let a = post(
        &s.app,
        "/v1/reconstructions?support=2&max-memory-mib=16&wait=60",
        "text/plain",
        sphere_xyz(3000, 17),
    )
    .await;
    assert_eq!(
        a.expect_error(StatusCode::UNPROCESSABLE_ENTITY),
        "system_too_large"
    );
    let v = a.json();
    assert!(
        v["error"]["message"].as_str().unwrap().contains("budget"),
        "{v}"
    );
    assert!(s.state.jobs.list().is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sse_streams_progress_then_done() {
    let s = start(|_| {});
    // Keep the worker busy so the second job is observed from `queued` onwards, then cancel
    // the first one to let the second run.
    let first = post(
        &s.app,
        "/v1/reconstructions?resolution=200",
        "text/plain",
        sphere_xyz(20000, 8),
    )
    .await;
    assert_eq!(first.status, StatusCode::ACCEPTED);
    let first_id = first.json()["id"].as_str().unwrap().to_string();
    let second = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}"),
        "text/plain",
        sphere_xyz(2000, 9),
    )
    .await;
    assert_eq!(second.status, StatusCode::ACCEPTED);
    assert!(
        second.headers["location"]
            .to_str()
            .unwrap()
            .starts_with("/v1/reconstructions/")
    );
    let id = second.json()["id"].as_str().unwrap().to_string();
    let app = s.app.clone();
    let events =
        tokio::spawn(async move { get(&app, &format!("/v1/reconstructions/{id}/events")).await });
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(
        delete(&s.app, &format!("/v1/reconstructions/{first_id}"))
            .await
            .status,
        StatusCode::ACCEPTED
    );
    let ev = events.await.unwrap();
    assert_eq!(ev.status, StatusCode::OK);
    assert_eq!(ev.headers["content-type"], "text/event-stream");
    let text = String::from_utf8(ev.body).unwrap();
    let mut events = Vec::new();
    for block in text.split("\n\n").filter(|b| !b.trim().is_empty()) {
        let name = block
            .lines()
            .find_map(|l| l.strip_prefix("event: "))
            .unwrap_or("");
        let data = block
            .lines()
            .find_map(|l| l.strip_prefix("data: "))
            .unwrap_or("null");
        events.push((
            name.to_string(),
            serde_json::from_str::<serde_json::Value>(data).unwrap(),
        ));
    }
    assert!(events.len() >= 3, "{text}");
    assert_eq!(events[0].1["status"], "queued");
    let stages: Vec<&str> = events
        .iter()
        .filter_map(|e| e.1["stage"].as_str())
        .collect();
    assert!(stages.contains(&"polygonize"), "{stages:?}");
    let progress: Vec<f64> = events
        .iter()
        .map(|e| e.1["progress"].as_f64().unwrap())
        .collect();
    assert!(progress.windows(2).all(|w| w[1] >= w[0]), "{progress:?}");
    let (last_name, last) = events.last().unwrap();
    assert_eq!(last_name, "done");
    assert_eq!(last["status"], "succeeded");
    assert!(events[..events.len() - 1].iter().all(|e| e.0 == "progress"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_stops_a_running_job_then_delete_removes_it() {
    let s = start(|_| {});
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=200",
        "text/plain",
        sphere_xyz(20000, 10),
    )
    .await;
    assert_eq!(a.status, StatusCode::ACCEPTED);
    let id = a.json()["id"].as_str().unwrap().to_string();
    let queued = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}"),
        "text/plain",
        sphere_xyz(200, 11),
    )
    .await;
    let queued_id = queued.json()["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    while get(&s.app, &format!("/v1/reconstructions/{id}"))
        .await
        .json()["status"]
        != "running"
    {
        assert!(t.elapsed() < Duration::from_secs(20), "never started");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let d = delete(&s.app, &format!("/v1/reconstructions/{id}")).await;
    assert_eq!(d.status, StatusCode::ACCEPTED);
    let t = Instant::now();
    let v = wait_terminal(&s.app, &id, 30).await;
    assert_eq!(v["status"], "cancelled", "{v}");
    assert_eq!(v["error"]["code"], "cancelled");
    assert!(
        t.elapsed() < Duration::from_secs(10),
        "cancel took {:?}",
        t.elapsed()
    );
    assert_eq!(
        get(&s.app, &format!("/v1/reconstructions/{id}/mesh.glb"))
            .await
            .expect_error(StatusCode::CONFLICT),
        "not_ready"
    );
    // The worker survived and runs the next job.
    assert_eq!(
        wait_terminal(&s.app, &queued_id, 60).await["status"],
        "succeeded"
    );
    assert_eq!(
        delete(&s.app, &format!("/v1/reconstructions/{id}"))
            .await
            .status,
        StatusCode::NO_CONTENT
    );
    assert_eq!(
        get(&s.app, &format!("/v1/reconstructions/{id}"))
            .await
            .expect_error(StatusCode::NOT_FOUND),
        "not_found"
    );
    assert!(!s.dir.path().join(&id).exists(), "files removed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_over_its_time_limit_fails_clearly() {
    let s = start(|c| c.job_timeout = Duration::from_millis(30));
    let a = post(
        &s.app,
        "/v1/reconstructions?resolution=200&wait=60",
        "text/plain",
        sphere_xyz(20000, 12),
    )
    .await;
    // A time limit is a limit: 4xx (422), like the other limits.
    assert_eq!(
        a.status,
        StatusCode::UNPROCESSABLE_ENTITY,
        "{}",
        String::from_utf8_lossy(&a.body)
    );
    let v = a.json();
    assert_eq!(v["error"]["code"], "job_timeout");
    assert!(
        v["error"]["message"]
            .as_str()
            .unwrap()
            .contains("time limit")
    );
    assert_eq!(v["job"]["status"], "failed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn restart_serves_stored_results_and_recovers_unfinished_jobs() {
    let s = start(|_| {});
    let a = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}&wait=60"),
        "text/plain",
        sphere_xyz(300, 13),
    )
    .await;
    assert_eq!(a.status, StatusCode::OK);
    let done = a.json();
    let id = done["id"].as_str().unwrap().to_string();
    let glb_before = get(&s.app, &format!("/v1/reconstructions/{id}/mesh.glb"))
        .await
        .body;
    let jobs = s.state.jobs.clone();
    tokio::task::spawn_blocking(move || jobs.shutdown())
        .await
        .unwrap();
    // Fake two unfinished jobs as a crash would leave them: one queued, one running.
    let fake = |status: &str| {
        let nid = uuid::Uuid::new_v4().to_string();
        let dst = s.dir.path().join(&nid);
        std::fs::create_dir_all(&dst).unwrap();
        for f in ["input.xyz", "params.json"] {
            std::fs::copy(s.dir.path().join(&id).join(f), dst.join(f)).unwrap();
        }
        let mut st: serde_json::Value = serde_json::from_slice(
            &std::fs::read(s.dir.path().join(&id).join("status.json")).unwrap(),
        )
        .unwrap();
        st["id"] = nid.clone().into();
        st["status"] = status.into();
        st["finished_at"] = serde_json::Value::Null;
        st["triangles"] = serde_json::Value::Null;
        std::fs::write(dst.join("status.json"), serde_json::to_vec(&st).unwrap()).unwrap();
        nid
    };
    let (queued, running) = (fake("queued"), fake("running"));
    let state = start_on(s.dir.path(), |_| {});
    let app = rbfsurf::server::router(state);
    let list = get(&app, "/v1/reconstructions").await.json();
    assert_eq!(list.as_array().unwrap().len(), 3);
    let again = get(&app, &format!("/v1/reconstructions/{id}")).await.json();
    assert_eq!(again["status"], "succeeded");
    assert_eq!(again["report"], done["report"]);
    assert_eq!(
        get(&app, &format!("/v1/reconstructions/{id}/mesh.glb"))
            .await
            .body,
        glb_before
    );
    let r = wait_terminal(&app, &running, 5).await;
    assert_eq!(
        (r["status"].as_str(), r["error"]["code"].as_str()),
        (Some("failed"), Some("interrupted"))
    );
    let q = wait_terminal(&app, &queued, 60).await;
    assert_eq!(q["status"], "succeeded", "re-queued job ran: {q}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn finished_jobs_expire() {
    let s = start(|c| c.expire_after = Some(Duration::ZERO));
    let a = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}&wait=60"),
        "text/plain",
        sphere_xyz(200, 14),
    )
    .await;
    let id = a.json()["id"].as_str().unwrap().to_string();
    let jobs = s.state.jobs.clone();
    assert_eq!(
        tokio::task::spawn_blocking(move || jobs.expire())
            .await
            .unwrap(),
        1
    );
    assert_eq!(
        get(&s.app, &format!("/v1/reconstructions/{id}"))
            .await
            .expect_error(StatusCode::NOT_FOUND),
        "not_found"
    );
    assert!(!s.dir.path().join(&id).exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn random_requests_never_break_the_server() {
    let s = start(|c| c.max_points = 5000);
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let types = [
        "application/ply",
        "text/plain",
        "text/csv",
        "model/obj",
        "application/octet-stream",
        "multipart/form-data; boundary=x",
        "image/png",
    ];
    let good = sphere_xyz(200, 15);
    let ply = b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n".to_vec();
    for round in 0..300 {
        let base = if round % 2 == 0 { &good } else { &ply };
        let mut body = base[..(next() as usize % (base.len() + 1))].to_vec();
        for _ in 0..next() % 8 {
            if !body.is_empty() {
                let i = next() as usize % body.len();
                body[i] = next() as u8;
            }
        }
        let ct = types[next() as usize % types.len()];
        let a = post(&s.app, "/v1/reconstructions?resolution=16", ct, body).await;
        match a.status.as_u16() {
            202 => {}
            400 | 413 | 415 | 422 => {
                a.expect_error(a.status);
            }
            other => panic!(
                "round {round}: unexpected {other}: {}",
                String::from_utf8_lossy(&a.body)
            ),
        }
    }
    // Every accepted job ends in a terminal state and the worker is alive.
    for j in s.state.jobs.list() {
        let v = wait_terminal(&s.app, &j.id.to_string(), 60).await;
        assert!(
            matches!(v["status"].as_str(), Some("succeeded" | "failed")),
            "{v}"
        );
    }
    let a = post(
        &s.app,
        &format!("/v1/reconstructions?{SMALL}&wait=60"),
        "text/plain",
        sphere_xyz(300, 16),
    )
    .await;
    assert_eq!(a.json()["status"], "succeeded");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cors_answers_only_configured_origins() {
    let s = start(|c| c.cors_origins = vec!["https://a.example".into()]);
    let pre = |origin: &str| {
        Request::options("/v1/reconstructions")
            .header("origin", origin)
            .header("access-control-request-method", "POST")
            .body(Body::empty())
            .unwrap()
    };
    let ok = send(&s.app, pre("https://a.example")).await;
    assert_eq!(
        ok.headers["access-control-allow-origin"],
        "https://a.example"
    );
    let other = send(&s.app, pre("https://evil.example")).await;
    assert!(!other.headers.contains_key("access-control-allow-origin"));
    let none = start(|_| {});
    let a = send(&none.app, pre("https://a.example")).await;
    assert!(
        !a.headers.contains_key("access-control-allow-origin"),
        "CORS is off by default"
    );
}

#[tokio::test]
async fn viewer_page_health_and_openapi_are_served() {
    let s = start(|_| {});
    let page = get(&s.app, "/").await;
    assert_eq!(page.status, StatusCode::OK);
    let html = String::from_utf8(page.body).unwrap();
    assert!(
        html.contains("/assets/viewer.js")
            && !html.contains("http://")
            && !html.contains("https://"),
        "no CDN"
    );
    let js = get(&s.app, "/assets/viewer.js").await;
    assert!(
        String::from_utf8(js.body)
            .unwrap()
            .contains("loaded ${mesh.indices.length / 3} triangles")
    );
    assert_eq!(get(&s.app, "/healthz").await.json()["status"], "ok");
    let doc = get(&s.app, "/openapi.json").await.json();
    assert!(doc["paths"]["/v1/reconstructions/{id}/events"].is_object());
}

#[test]
fn openapi_document_matches_proto() {
    let generated = rbfsurf::server::openapi::openapi_json();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("proto/openapi.json");
    if std::env::var_os("UPDATE_OPENAPI").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let stored = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        stored == generated,
        "proto/openapi.json is out of date: run `cargo run -- openapi -o proto/openapi.json` (or UPDATE_OPENAPI=1 cargo test --test service http::)"
    );
    // Every documented parameter of the upload is a ReconOptions field (one shared definition).
    let doc: serde_json::Value = serde_json::from_str(&generated).unwrap();
    let names: Vec<&str> = doc["paths"]["/v1/reconstructions"]["post"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    for n in [
        "kernel",
        "support",
        "neighbours",
        "resolution",
        "leaf-size",
        "wait",
    ] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
}

/// Every error code the server's sources can emit (`ApiError::new(STATUS, "code", …)`,
/// `code: "…"` literals in src/server and src/dist, and the library's `ErrorKind` codes) is named
/// in the document's `ErrorBody.code` description.
#[test]
fn openapi_error_codes_name_every_code_the_server_emits() {
    fn sources(dir: &std::path::Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                sources(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(std::fs::read_to_string(&p).unwrap());
            }
        }
    }
    /// The first string literal after each occurrence of `marker` (within `reach` bytes).
    fn literals_after(text: &str, marker: &str, reach: usize, out: &mut Vec<String>) {
        for (at, _) in text.match_indices(marker) {
            let tail = &text[at + marker.len()..];
            let tail = &tail[..tail.len().min(reach)];
            let mut parts = tail.split('"');
            if let (Some(_), Some(lit)) = (parts.next(), parts.next()) {
                out.push(lit.to_string());
            }
        }
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut texts = Vec::new();
    sources(&root.join("server"), &mut texts);
    sources(&root.join("dist"), &mut texts);
    let mut codes = Vec::new();
    for t in &texts {
        literals_after(t, "ApiError::new(", 120, &mut codes);
        for (at, _) in t.match_indices("code: \"") {
            let lit = t[at + 7..].split('"').next().unwrap();
            codes.push(lit.to_string());
        }
    }
    let kinds = std::fs::read_to_string(root.join("error.rs")).unwrap();
    for (at, _) in kinds.match_indices(" => \"") {
        let lit = kinds[at + 5..].split('"').next().unwrap();
        codes.push(lit.to_string());
    }
    codes.sort();
    codes.dedup();
    assert!(
        codes.len() >= 20 && codes.iter().any(|c| c == "job_store_unavailable"),
        "the scan found too little: {codes:?}"
    );
    let doc: serde_json::Value =
        serde_json::from_str(&rbfsurf::server::openapi::openapi_json()).unwrap();
    let described = doc["components"]["schemas"]["ErrorBody"]["properties"]["code"]["description"]
        .as_str()
        .unwrap();
    let missing: Vec<&String> = (codes.iter())
        .filter(|c| c.chars().all(|ch| ch.is_ascii_lowercase() || ch == '_'))
        .filter(|c| !described.contains(&format!("`{c}`")))
        .collect();
    assert!(
        missing.is_empty(),
        "error codes the server emits but the OpenAPI document does not name: {missing:?}"
    );
}

/// The published constraints are the enforced ones: every enumerated value is accepted and any
/// other refused; each numeric bound is accepted and the value just outside it refused.
#[test]
fn openapi_parameter_constraints_are_the_servers() {
    use rbfsurf::server::routes::parse_params;
    let cfg = rbfsurf::job::ServerConfig {
        max_resolution: 4096,
        ..Default::default()
    };
    let doc: serde_json::Value =
        serde_json::from_str(&rbfsurf::server::openapi::openapi_json()).unwrap();
    let params = doc["paths"]["/v1/reconstructions"]["post"]["parameters"]
        .as_array()
        .unwrap();
    let ok = |name: &str, v: &str| parse_params(&[(name.to_string(), v.to_string())], &cfg);
    let mut checked = 0;
    for p in params {
        let name = p["name"].as_str().unwrap();
        let schema = &p["schema"];
        if let Some(values) = schema["enum"].as_array() {
            for v in values {
                assert!(ok(name, v.as_str().unwrap()).is_ok(), "{name}={v}");
            }
            assert!(ok(name, "bogus").is_err(), "{name}=bogus");
            checked += 1;
        } else if schema.get("pattern").is_some() {
            assert!(
                ok(name, "auto").is_ok() && ok(name, "0999").is_err(),
                "{name}"
            );
            checked += 1;
        } else {
            let integer = schema["type"] == "integer";
            let step = if integer { 1.0 } else { 1e-9 };
            let fmt = |v: f64| {
                if integer {
                    format!("{}", v as i64)
                } else {
                    format!("{v}")
                }
            };
            if let Some(min) = schema["minimum"].as_f64() {
                assert!(ok(name, &fmt(min)).is_ok(), "{name}={min}");
                assert!(ok(name, &fmt(min - step)).is_err(), "{name} below {min}");
            } else if let Some(min) = schema["exclusiveMinimum"].as_f64() {
                assert!(ok(name, &fmt(min)).is_err(), "{name}={min} (exclusive)");
                assert!(ok(name, &fmt(min + 1e-6)).is_ok(), "{name} above {min}");
            } else {
                panic!("{name}: no constraint in {schema}");
            }
            if let Some(max) = schema["maximum"].as_f64() {
                assert!(ok(name, &fmt(max)).is_ok(), "{name}={max}");
                assert!(
                    ok(name, &fmt(max + step * max.max(1.0))).is_err(),
                    "{name} above {max}"
                );
            }
            checked += 1;
        }
    }
    assert_eq!(checked, params.len());
    let sse = &doc["paths"]["/v1/reconstructions/{id}/events"]["get"]["responses"]["200"];
    assert!(sse.to_string().contains("event: progress"), "{sse}");
}
