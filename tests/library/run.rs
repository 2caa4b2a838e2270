//! `pipeline::run`, the one read → reconstruct → write stage of the command line and the server:
//! both sources give the same mesh and report, every failure has its kind and leaves no file.

use crate::common;
use rbfsurf::error::ErrorKind;
use rbfsurf::io::{MeshFormat, PointFormat, ReadLimits, read_mesh};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::{PointSource, RunOutput, run};
use rbfsurf::progress::{CancelFlag, NoProgress};
use std::path::Path;

fn output<'a>(mesh: &'a Path, report: &'a Path) -> RunOutput<'a> {
    RunOutput {
        mesh,
        // Plain GLB: the test compares triangle counts with the report exactly (the compact GLB
        // merges vertices on its 16-bit grid, see docs/formats.md).
        format: MeshFormat::Glb(rbfsurf::io::GlbOptions::compressed(
            rbfsurf::io::GlbCompression::None,
        )),
        report: Some(report),
        field: None,
        job_memory_mib: None,
    }
}

#[test]
fn a_file_and_its_bytes_give_the_same_mesh_and_a_complete_report() {
    let dir = tempfile::tempdir().unwrap();
    let input = common::data("kitten.ply");
    let (m1, r1) = (dir.path().join("a.glb"), dir.path().join("a.json"));
    let (m2, r2) = (dir.path().join("b.glb"), dir.path().join("b.json"));
    let p = ReconParams::default();
    let limits = ReadLimits::default();
    let a = run(
        PointSource::File(&input),
        &p,
        &limits,
        &output(&m1, &r1),
        &NoProgress,
    )
    .unwrap();
    let bytes = std::fs::read(&input).unwrap();
    let source = PointSource::Bytes {
        data: &bytes,
        format: PointFormat::Ply,
    };
    let b = run(source, &p, &limits, &output(&m2, &r2), &NoProgress).unwrap();
    let (ma, mb) = (read_mesh(&m1).unwrap(), read_mesh(&m2).unwrap());
    assert_eq!(ma.triangles.len(), a.triangles);
    assert_eq!(ma.vertices, mb.vertices);
    assert_eq!(ma.triangles, mb.triangles);
    assert_eq!(a.report.mesh.genus, Some(1));
    let t = &b.report.timings_s;
    assert!(t.read > 0.0 && t.write > 0.0, "{t:?}");
    // The total is the whole run, measured once: no sum of stages can exceed it.
    assert!(t.total >= t.read + t.polygonize + t.write, "{t:?}");
    // The kitten has normals: none estimated.
    assert_eq!(t.normals, 0.0);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&r2).unwrap()).unwrap();
    assert_eq!(json["timings_s"]["total"].as_f64(), Some(t.total));
    assert!(json["memory"]["peak_rss_mib"].as_f64().unwrap() > 0.0);
}

#[test]
fn estimating_normals_is_a_timed_stage_of_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let cloud =
        rbfsurf::io::read_point_cloud(&common::data("kitten.ply"), &ReadLimits::default()).unwrap();
    let text: String = cloud
        .points
        .iter()
        .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
        .collect();
    let (mesh, report) = (dir.path().join("x.glb"), dir.path().join("x.json"));
    let source = PointSource::Bytes {
        data: text.as_bytes(),
        format: PointFormat::Xyz,
    };
    let p = ReconParams::default();
    let r = run(
        source,
        &p,
        &ReadLimits::default(),
        &output(&mesh, &report),
        &NoProgress,
    )
    .unwrap();
    let t = &r.report.timings_s;
    assert!(t.normals > 0.0, "{t:?}");
    assert!(t.total >= t.normals + t.polygonize, "{t:?}");
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["timings_s"]["normals"].as_f64(), Some(t.normals));
}

#[test]
fn failures_have_their_kind_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, report) = (dir.path().join("x.glb"), dir.path().join("x.json"));
    let out = output(&mesh, &report);
    let p = ReconParams::default();
    let limits = ReadLimits::default();
    let bytes = |data: &'static [u8], format| PointSource::Bytes { data, format };
    let binary = dir.path().join("cloud.bin");
    std::fs::write(&binary, [0u8, 1, 2, 255, 0, 7, 9, 0]).unwrap();
    let cases: [(PointSource, ErrorKind); 4] = [
        (
            bytes(b"ply\nformat nonsense\n", PointFormat::Ply),
            ErrorKind::InvalidInput,
        ),
        (
            bytes(b"0 0 0\n1 1 1\n2 2 2\n3 3 3\n4 4 4\n", PointFormat::Xyz),
            ErrorKind::Unreconstructable,
        ),
        (
            PointSource::File(Path::new("/nonexistent/cloud.xyz")),
            ErrorKind::Internal,
        ),
        (PointSource::File(&binary), ErrorKind::UnsupportedFormat),
    ];
    for (source, kind) in cases {
        let err = run(source, &p, &limits, &out, &NoProgress).unwrap_err();
        assert_eq!(err.kind(), kind, "{err}");
        assert!(!mesh.exists() && !report.exists(), "{err}");
    }
    let tight = ReadLimits {
        max_points: 100,
        ..ReadLimits::default()
    };
    let input = common::data("kitten.ply");
    let err = run(PointSource::File(&input), &p, &tight, &out, &NoProgress).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::TooLarge, "{err}");
    let small = ReconParams {
        max_memory_mib: 16,
        ..ReconParams::default()
    };
    let err = run(
        PointSource::File(&input),
        &small,
        &limits,
        &out,
        &NoProgress,
    )
    .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::OverBudget, "{err}");
    let flag = CancelFlag::default();
    flag.cancel();
    let err = run(PointSource::File(&input), &p, &limits, &out, &flag).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Cancelled, "{err}");
    assert!(!mesh.exists() && !report.exists());
}
