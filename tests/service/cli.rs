//! The command line as a user meets it: bad input gives one line on stderr, a non-zero exit code and
//! no output file; good input gives a GLB and a report with the contract keys.

use crate::common;

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
    // A line as a file stores it: rounded to 6 decimals, so not exactly collinear; with normals
    // too. Both are refused as a curve instead of meshed into a tube around the points.
    let rounded: Vec<f64> = (0..500)
        .map(|i| (i as f64 * 0.618_033_988_7).fract())
        .collect();
    let line: String = (rounded.iter())
        .map(|t| format!("{t:.6} {:.6} {:.6}\n", 2.0 * t, 3.0 * t))
        .collect();
    assert_refused(&w("rounded_line.xyz", line.as_bytes()), &[], "curve");
    let line: String = (rounded.iter())
        .map(|t| format!("{t:.6} {:.6} {:.6} 0 0.6 -0.8\n", 2.0 * t, 3.0 * t))
        .collect();
    assert_refused(&w("rounded_line_n.xyz", line.as_bytes()), &[], "curve");
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
        &["--support", "1.5", "--max-memory-mib", "256"],
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
    // With an unlimited budget the body-size check refuses it (the file is 24 bytes long).
    let start = std::time::Instant::now();
    assert_refused(
        &p,
        &["--max-points", "200000000", "--max-memory-mib", "4194304"],
        "1200000000 bytes",
    );
    // The default 8 GiB budget reconstructs 10^8 points out of core (the prepare streams the
    // file): the header passes, and the body-size check refuses the 24-byte file before any read.
    assert_refused(&p, &["--max-points", "200000000"], "1200000000 bytes");
    // So does 1 GiB (the streamed prepare needs ~340 MiB for 10^8 points).
    assert_refused(
        &p,
        &["--max-points", "200000000", "--max-memory-mib", "1024"],
        "1200000000 bytes",
    );
    // A 256 MiB budget cannot hold even that: refused by the pre-read memory check.
    let out = tmp("e8.glb");
    let r = reconstruct(
        &p,
        &out,
        &["--max-points", "200000000", "--max-memory-mib", "256"],
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    for needle in [
        "100000000 points",
        "even out of core",
        "256 MiB",
        "--max-memory-mib",
    ] {
        assert!(r.stderr.contains(needle), "no '{needle}' in {:?}", r.stderr);
    }
    assert!(!out.exists());
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
    // 42,252 grid triangles, 11,218 after the default chord-error simplification (0.03 spacings,
    // measured; 7,590 at the earlier 0.05).
    assert!(mesh.triangles.len() > 5_000);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let before = v["polygonize"]["triangles_before_simplify"]
        .as_u64()
        .unwrap();
    assert!(before > 3 * mesh.triangles.len() as u64, "{before}");
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

fn generate(shape: &str, points: usize, extra: &[&str], out: &Path) {
    let o = bin()
        .args(["generate", shape, "--points", &points.to_string(), "-o"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn read_points(p: &Path) -> rbfsurf::geometry::PointCloud {
    rbfsurf::io::read_point_cloud(p, &rbfsurf::io::ReadLimits::default()).unwrap()
}

#[test]
fn generate_writes_noisy_points_and_a_closed_truth_mesh_of_the_right_genus() {
    use rbfsurf::geometry::synthetic::Shape;
    for (shape, genus) in [("knot", 1), ("bumpy-sphere", 0)] {
        let (out, truth) = (
            tmp(&format!("{shape}.ply")),
            tmp(&format!("{shape}-truth.ply")),
        );
        generate(
            shape,
            5000,
            &["--noise", "0.004", "--truth", truth.to_str().unwrap()],
            &out,
        );
        let cloud = read_points(&out);
        assert_eq!(cloud.points.len(), 5000);
        assert!(cloud.normals.is_some());
        let mesh = rbfsurf::io::read_mesh(&truth).unwrap();
        assert!(mesh.triangles.len() >= 400_000, "{}", mesh.triangles.len());
        let t = rbfsurf::mesh::analyze(&mesh);
        assert!(t.watertight && t.manifold && t.oriented, "{shape}: {t:?}");
        assert_eq!((t.components, t.genus), (1, Some(genus)), "{shape}");
        // Noise σ = 0.004 D along random directions: the normal component has RMS σ/√3
        // (the knot's distance is exact; the bumpy sphere's is first-order, still good to a few %).
        let s = Shape::by_name(shape).unwrap();
        let d = rbfsurf::geometry::Aabb::from_points(&s.sample(5000, 1).points).diagonal();
        let rms = (cloud
            .points
            .iter()
            .map(|p| s.signed_distance(p).powi(2))
            .sum::<f64>()
            / 5000.0)
            .sqrt();
        let want = 0.004 * d / 3f64.sqrt();
        assert!(
            (rms / want - 1.0).abs() < 0.08,
            "{shape}: rms {rms} vs {want}"
        );
    }
}

#[test]
fn generate_outliers_holes_open_and_no_normals() {
    use rbfsurf::geometry::synthetic::Shape;
    let sphere = Shape::by_name("sphere").unwrap();
    let out = tmp("sphere-outliers.ply");
    generate("sphere", 4000, &["--outliers", "0.05"], &out);
    let c = read_points(&out);
    assert_eq!(c.points.len(), 4000);
    // Positions are written as doubles, so the surface points are on the sphere to rounding.
    let off = c
        .points
        .iter()
        .filter(|p| sphere.signed_distance(p).abs() > 1e-9)
        .count();
    assert_eq!(off, 200);

    let (a, b) = (tmp("holes-a.ply"), tmp("holes-b.ply"));
    generate("torus", 10_000, &["--holes", "4", "--no-normals"], &a);
    generate("torus", 10_000, &["--holes", "4", "--no-normals"], &b);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let c = read_points(&a);
    assert!(c.normals.is_none());
    // Four holes of radius ρ = 0.08 D (D = 1.21) on a torus of area 4π² · 0.3 · 0.12 = 1.42: each
    // removes about πρ² / 1.42 = 2.1% of the points (they may overlap).
    let removed = 10_000 - c.points.len();
    assert!((150..=1000).contains(&removed), "{removed} removed");

    let open = tmp("sphere-open.ply");
    generate("sphere", 6000, &["--open", "--offset", "1e6"], &open);
    let c = read_points(&open);
    assert!(
        (c.points.len() as f64 - 3000.0).abs() < 200.0,
        "{}",
        c.points.len()
    );
    assert!(c.points.iter().all(|p| p[2] >= 1e6 + 0.5 - 1e-9));
    let o = bin()
        .args(["generate", "cube", "-o"])
        .arg(tmp("cube.ply"))
        .output()
        .unwrap();
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("knot"));
}

#[test]
fn serve_refuses_a_zero_queue_and_an_empty_token_file_at_start() {
    let out = bin()
        .args(["serve", "--max-queue", "0", "--addr", "127.0.0.1:0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--max-queue 0"), "{err}");
    let empty = tmp("empty-token");
    std::fs::write(&empty, "\n").unwrap();
    let out = bin()
        .args(["serve", "--addr", "127.0.0.1:0", "--token-file"])
        .arg(&empty)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("empty"));
}
