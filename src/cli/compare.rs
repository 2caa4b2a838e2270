//! `rbfsurf compare MESH REFERENCE [--samples N] [--json]`.

use super::outln;
use crate::io::{ReadLimits, read_mesh, read_point_cloud};
use crate::mesh::compare::{CompareParams, Reference, compare};
use crate::mesh::topology::analyze;
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Arguments of `compare`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The mesh to measure (GLB, PLY, OBJ, OFF).
    pub mesh: PathBuf,
    /// The reference: a mesh (GLB, PLY with faces, OBJ, OFF) or a point set (any point format).
    pub reference: PathBuf,
    /// Samples per surface.
    #[arg(long, default_value_t = 100_000)]
    pub samples: usize,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &CompareArgs) -> Result<()> {
    let mesh = read_mesh(&a.mesh).with_context(|| format!("reading {}", a.mesh.display()))?;
    let ref_mesh = read_mesh(&a.reference)
        .ok()
        .filter(|m| !m.triangles.is_empty());
    let ref_points;
    let reference = match &ref_mesh {
        Some(m) => Reference::Mesh(m),
        None => {
            ref_points = read_point_cloud(&a.reference, &ReadLimits::default())
                .with_context(|| format!("reading {}", a.reference.display()))?
                .points;
            Reference::Points(&ref_points)
        }
    };
    let params = CompareParams {
        samples: a.samples,
        ..Default::default()
    };
    let r = compare(&mesh, reference, &params)?;
    let mesh_topo = analyze(&mesh);
    let ref_topo = ref_mesh.as_ref().map(analyze);
    if a.json {
        let v = serde_json::json!({
            "chamfer_rel": r.chamfer_rel, "hausdorff_rel": r.hausdorff_rel,
            "mesh_to_ref_mean_rel": r.mesh_to_ref_mean_rel, "ref_to_mesh_mean_rel": r.ref_to_mesh_mean_rel,
            "mesh_to_ref_plane_mean_rel": r.mesh_to_ref_plane_mean_rel,
            "samples": r.samples, "mesh": mesh_topo, "reference": ref_topo,
        });
        outln!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        outln!(
            "chamfer_rel   {:.3e}  (mean of {:.3e} mesh→ref and {:.3e} ref→mesh)",
            r.chamfer_rel,
            r.mesh_to_ref_mean_rel,
            r.ref_to_mesh_mean_rel
        );
        outln!("hausdorff_rel {:.3e}", r.hausdorff_rel);
        if let Some(p) = r.mesh_to_ref_plane_mean_rel {
            outln!(
                "mesh→scan surface {p:.3e}  (mean distance to the plane of the 8 nearest points)"
            );
        }
        outln!("samples       {}", r.samples);
        outln!(
            "mesh          {} vertices, {} triangles, {} component(s), watertight {}, genus {}",
            mesh_topo.vertices,
            mesh_topo.triangles,
            mesh_topo.components,
            mesh_topo.watertight,
            mesh_topo.genus_label()
        );
    }
    Ok(())
}
