//! The out-of-core task graph (`rbfsurf::pipeline::tiled`): the same mesh from the in-memory and
//! the on-disk store, whatever the region size (seams weld exactly), against analytic truth and
//! against the in-memory pipeline; `run` switches to it when the budget requires.

use crate::common;

use rbfsurf::geometry::TriMesh;
use rbfsurf::geometry::synthetic::Shape;
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::tiled::{StoreKind, TiledOptions, reconstruct_tiled};
use rbfsurf::progress::NoProgress;

fn options(store: StoreKind, region_cells: usize, concurrency: usize) -> TiledOptions {
    TiledOptions {
        store,
        block_points: Some(2000),
        region_cells,
        concurrency: Some(concurrency),
        worker: "test".into(),
    }
}

/// The triangles as sorted triples of vertex position bits (independent of vertex order and of
/// the rotation of each triangle's indices), sorted.
fn canonical(mesh: &TriMesh) -> Vec<[[u64; 3]; 3]> {
    let mut tris: Vec<[[u64; 3]; 3]> = (mesh.triangles.iter())
        .map(|t| {
            let v = t.map(|i| mesh.vertices[i as usize].map(f64::to_bits));
            // Rotate so the smallest vertex comes first (keeps the winding).
            let k = (0..3).min_by_key(|&k| v[k]).unwrap_or(0);
            [v[k], v[(k + 1) % 3], v[(k + 2) % 3]]
        })
        .collect();
    tris.sort_unstable();
    tris
}

#[test]
fn memory_and_disk_stores_and_any_region_size_give_the_same_closed_torus() {
    let shape = Shape::by_name("torus").unwrap();
    let cloud = shape.sample(12_000, 31);
    let params = ReconParams::default();
    let one = reconstruct_tiled(
        cloud.clone(),
        &params,
        &options(StoreKind::Memory, 4096, 1),
        &NoProgress,
    )
    .unwrap();
    let many = reconstruct_tiled(
        cloud.clone(),
        &params,
        &options(StoreKind::TempDir(None), 16, 2),
        &NoProgress,
    )
    .unwrap();
    let r = &many.report;
    assert!(r.blocks.len() >= 6, "{} blocks", r.blocks.len());
    assert_eq!(r.matrix.blocks, r.blocks.len());
    assert!(r.blocks.iter().all(|b| b.worker == "test" && b.points > 0));
    assert!(r.matrix.n > 12_000, "overlaps duplicate points");
    for rec in [&one, &many] {
        let m = &rec.report.mesh;
        assert!(m.watertight && m.manifold && m.components == 1, "{m:?}");
        assert_eq!(m.genus, Some(1));
        assert!(rec.report.residual.max < 1e-8, "{:?}", rec.report.residual);
        let err = common::max_vertex_error(&rec.mesh, |p| shape.signed_distance(p));
        assert!(err < 0.01, "max vertex error {err}");
    }
    // One region holding everything vs regions of 16 cells (dozens of seams): the same triangles,
    // bit for bit.
    assert_eq!(one.mesh.triangles.len(), many.mesh.triangles.len());
    assert!(
        canonical(&one.mesh) == canonical(&many.mesh),
        "meshes differ"
    );
    // And close to the in-memory pipeline with the same block size.
    let in_memory = rbfsurf::reconstruct(
        &cloud,
        &ReconParams {
            blocks: rbfsurf::rbf::Blocks::MaxPoints(2000),
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let d = rbfsurf::mesh::compare::compare(
        &many.mesh,
        rbfsurf::mesh::compare::Reference::Mesh(&in_memory.mesh),
        &Default::default(),
    )
    .unwrap();
    assert!(d.chamfer_rel < 1e-4, "{d:?}");
}

#[test]
fn run_goes_out_of_core_when_the_budget_requires_and_refuses_what_it_cannot_do() {
    let shape = Shape::by_name("sphere").unwrap();
    let cloud = shape.sample(60_000, 32);
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.ply");
    rbfsurf::io::write_points_ply(&input, &cloud).unwrap();
    let mesh = dir.path().join("sphere-mesh.ply");
    let budget = 130;
    let over = rbfsurf::pipeline::estimated_peak_mib(60_000);
    assert!(
        over > budget as f64,
        "in-memory estimate {over} must exceed the budget"
    );
    let params = ReconParams {
        max_memory_mib: budget,
        ..Default::default()
    };
    let output = rbfsurf::pipeline::RunOutput {
        mesh: &mesh,
        format: rbfsurf::io::MeshFormat::Ply,
        report: None,
        field: None,
        job_memory_mib: None,
    };
    let source = rbfsurf::pipeline::PointSource::File(&input);
    let summary =
        rbfsurf::pipeline::run(source, &params, &Default::default(), &output, &NoProgress).unwrap();
    let r = &summary.report;
    assert!(
        r.blocks.len() >= 2,
        "{} blocks: out of core",
        r.blocks.len()
    );
    assert!(r.mesh.watertight && r.mesh.components == 1 && r.mesh.genus == Some(0));
    // The file holds the mesh (a vertex pair closer than f32 precision may read back as one,
    // as for the in-memory pipeline: measured 978,142 of 978,144 triangles both ways).
    let back = rbfsurf::io::read_mesh(&mesh).unwrap();
    let lost = summary.triangles - back.triangles.len();
    assert!(lost <= summary.triangles / 10_000, "{lost} triangles lost");
    // Out-of-core cannot trim an open surface: a clear refusal, no output.
    std::fs::remove_file(&mesh).unwrap();
    let trim = ReconParams {
        boundary: rbfsurf::params::Boundary::Trim,
        ..params.clone()
    };
    let e = rbfsurf::pipeline::run(source, &trim, &Default::default(), &output, &NoProgress)
        .unwrap_err();
    assert!(
        e.to_string().contains("refuse") || e.to_string().contains("budget"),
        "{e}"
    );
    assert!(!mesh.exists());
}
