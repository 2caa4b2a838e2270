//! The command line as a user meets it: bad input gives one line on stderr, a non-zero exit code and
//! no output file; good input gives a GLB and a report with the contract keys.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rbfsurf"))
}

struct Run {
    code: i32,
    stderr: String,
}

fn reconstruct(input: &Path, out: &Path, extra: &[&str]) -> Run {
    let o = bin()
        .arg("reconstruct")
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    Run {
        code: o.status.code().unwrap_or(-1),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rbfsurf-cli-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn assert_refused(input: &Path, extra: &[&str], needle: &str) {
    let out = tmp(&format!(
        "{}.glb",
        input.file_name().unwrap().to_string_lossy()
    ));
    let _ = std::fs::remove_file(&out);
    let r = reconstruct(input, &out, extra);
    assert!(
        r.code != 0 && r.code < 100,
        "{}: exit {}",
        input.display(),
        r.code
    );
    assert_eq!(
        r.stderr.trim_end().lines().count(),
        1,
        "{}: stderr {:?}",
        input.display(),
        r.stderr
    );
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    assert!(
        r.stderr.to_lowercase().contains(&needle.to_lowercase()),
        "{}: expected '{needle}' in {:?}",
        input.display(),
        r.stderr
    );
    assert!(!out.exists(), "{}: output written", input.display());
}

#[test]
fn bad_inputs_get_one_line_errors_and_no_output() {
    let w = |name: &str, bytes: &[u8]| {
        let p = tmp(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    assert_refused(&w("empty.xyz", b""), &[], "empty");
    assert_refused(
        &w("nan.xyz", b"nan nan nan\nnan 1 2\ninf 0 0\n"),
        &[],
        "NaN",
    );
    assert_refused(&w("three.xyz", b"0 0 0\n1 0 0\n0 1 0\n"), &[], "distinct");
    let line: String = (0..50).map(|i| format!("{i} {} 0\n", 2 * i)).collect();
    assert_refused(&w("line.xyz", line.as_bytes()), &[], "line");
    let plane: String = (0..100)
        .map(|i| format!("{} {} 1\n", i % 10, i / 10))
        .collect();
    assert_refused(&w("plane.xyz", plane.as_bytes()), &[], "normals");
    assert_refused(
        &w("junk.bin", &[0u8, 159, 146, 150, 7, 255, 1, 2, 3]),
        &[],
        "format",
    );
    let mut trunc = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    trunc.extend_from_slice(&[0u8; 100]);
    assert_refused(&w("trunc.ply", &trunc), &[], "truncated");
    let huge = b"ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
    assert_refused(&w("huge.ply", huge), &[], "1000000000");
    assert_refused(
        &common::data("bunny_cgal_10k.ply"),
        &["--support", "1.5", "--max-memory-mib", "64"],
        "MiB",
    );
    assert_refused(&common::data("kitten.ply"), &["--support", "-1"], "support");
    assert_refused(
        &common::data("kitten.ply"),
        &["--resolution", "3"],
        "resolution",
    );
}

#[test]
fn hundred_million_vertex_headers_are_refused_before_reading() {
    let mut head = b"ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    head.extend_from_slice(&[0u8; 24]);
    let p = tmp("e8.ply");
    std::fs::write(&p, &head).unwrap();
    // Within the memory budget (2.2 GiB of points < 8 GiB): the body-size check refuses it.
    let start = std::time::Instant::now();
    assert_refused(&p, &["--max-points", "200000000"], "1200000000 bytes");
    // A 1 GiB budget cannot hold 10^8 points: refused by the pre-read memory check.
    let out = tmp("e8.glb");
    let r = reconstruct(
        &p,
        &out,
        &["--max-points", "200000000", "--max-memory-mib", "1024"],
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    for needle in [
        "100000000 points",
        "2289 MiB",
        "1024 MiB",
        "subsample",
        "--max-memory-mib",
    ] {
        assert!(r.stderr.contains(needle), "no '{needle}' in {:?}", r.stderr);
    }
    assert_refused(&p, &["--max-memory-mib", "1024"], "memory budget");
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
}

#[test]
fn unknown_output_format_and_missing_directory_are_refused_up_front() {
    let r = reconstruct(&common::data("kitten.ply"), &tmp("out.stl"), &[]);
    assert!(r.code != 0 && r.stderr.contains("stl"), "{:?}", r.stderr);
    let r = reconstruct(
        &common::data("kitten.ply"),
        Path::new("/nonexistent-dir/x.glb"),
        &[],
    );
    assert!(
        r.code != 0 && r.stderr.contains("does not exist"),
        "{:?}",
        r.stderr
    );
}

#[test]
fn kitten_reconstructs_to_a_valid_glb_with_a_full_report() {
    let out = tmp("kitten.glb");
    let report = tmp("kitten.json");
    let r = reconstruct(
        &common::data("kitten.ply"),
        &out,
        &["--report", report.to_str().unwrap(), "--quiet"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let mesh = rbfsurf::io::read_mesh(&out).unwrap();
    assert!(mesh.triangles.len() > 10_000);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    for key in [
        "input.points",
        "input.used",
        "input.dropped_non_finite",
        "input.merged_duplicates",
        "input.has_normals",
        "params.method",
        "params.kernel",
        "params.support",
        "params.carrier",
        "params.ordering",
        "params.solver",
        "matrix.n",
        "matrix.nnz",
        "matrix.bandwidth",
        "matrix.profile_values",
        "matrix.dense_values",
        "matrix.factor_values",
        "residual.rms",
        "residual.max",
        "mesh.vertices",
        "mesh.triangles",
        "mesh.components",
        "mesh.watertight",
        "mesh.manifold",
        "mesh.euler",
        "mesh.genus",
        "timings_s.read",
        "timings_s.assemble",
        "timings_s.factor",
        "timings_s.polygonize",
        "timings_s.write",
        "timings_s.total",
        "memory.peak_rss_mib",
    ] {
        let mut x = &v;
        for part in key.split('.') {
            x = &x[part];
        }
        assert!(!x.is_null(), "report lacks {key}");
    }
    assert_eq!(v["mesh"]["genus"], 1);
    assert_eq!(v["mesh"]["components"], 1);
    assert_eq!(v["input"]["points"], 5210);
    // The mesh is in input units: its bbox matches the points' bbox (diagonal 1.33) closely.
    let bb = rbfsurf::geometry::Aabb::from_points(&mesh.vertices);
    assert!(
        (bb.diagonal() - 1.33).abs() < 0.05,
        "diagonal {}",
        bb.diagonal()
    );
}

#[test]
fn compare_reports_json_with_the_contract_keys() {
    let out = tmp("bunny10k.glb");
    let r = reconstruct(&common::data("bunny_cgal_10k.ply"), &out, &["--quiet"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let o = bin()
        .arg("compare")
        .arg(&out)
        .arg(common::data("bunny00.off"))
        .args(["--json", "--samples", "20000"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for k in [
        "chamfer_rel",
        "hausdorff_rel",
        "mesh_to_ref_mean_rel",
        "ref_to_mesh_mean_rel",
        "samples",
        "mesh",
        "reference",
    ] {
        assert!(!v[k].is_null(), "compare lacks {k}");
    }
    assert!(v["chamfer_rel"].as_f64().unwrap() < 2e-3, "{v}");
}
