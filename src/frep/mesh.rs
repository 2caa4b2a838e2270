//! Polygonize a composite [`Solid`] with the sparse polygonizer: the meshing domain is the solid's
//! box ([`Solid::bounds`]) grown by three cells, mapped to the unit cube; cells are skipped by the
//! solid's value bound ([`Solid::bound`]); the mesh comes back in input units, outward normals,
//! GPU-ordered, with its topology.

use super::FrepError;
use super::ops::{Solid, SolidField};
use crate::geometry::{Aabb, Normalization, TriMesh};
use crate::mesh::topology::MeshTopology;
use crate::polygonize::{Everywhere, PolygonizeParams, Seeding, polygonize_in};
use crate::progress::Progress;
use serde::Serialize;
use std::time::Instant;

/// How finely to mesh a composite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsgParams {
    /// Grid cells along the longest edge of the solid's box (default 160).
    pub resolution: usize,
    /// Refuse grids with more cells than this.
    pub max_cells: u64,
    /// Root-finding steps per vertex along its grid edge (default 8: the R-functions' creases
    /// make linear interpolation land off the surface; each step is one evaluation per vertex).
    pub refine_steps: usize,
}

impl Default for CsgParams {
    fn default() -> Self {
        CsgParams {
            resolution: 160,
            max_cells: 1 << 30,
            refine_steps: 8,
        }
    }
}

/// What meshing a composite did (the `--report` of `rbfsurf csg`).
#[derive(Debug, Clone, Serialize)]
pub struct CsgReport {
    /// The expression as given.
    pub expression: String,
    /// Meshing domain, input units.
    pub domain: [[f64; 3]; 2],
    /// Grid cells along the longest edge.
    pub resolution: usize,
    /// Cell edge, input units.
    pub cell_size: f64,
    /// Blocks of the grid.
    pub blocks_total: usize,
    /// Blocks the bounds could not rule out (the only ones evaluated).
    pub blocks_active: usize,
    /// Field evaluations by the polygonizer.
    pub field_evaluations: u64,
    /// Topology of the mesh.
    pub mesh: MeshTopology,
    /// Seconds: loading the operands, polygonizing (incl. post).
    pub timings_s: CsgTimings,
}

/// Wall-clock seconds of a composite's stages.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct CsgTimings {
    /// Reading and parsing (filled by the caller).
    pub load: f64,
    /// Polygonization, GPU ordering and topology.
    pub mesh: f64,
    /// Everything (filled by the caller).
    pub total: f64,
}

/// Meshing domain of `solid`: its box grown by three cells of `resolution` along the longest edge.
pub fn meshing_domain(solid: &Solid, resolution: usize) -> Result<Aabb, FrepError> {
    let b = solid.bounds().ok_or_else(|| {
        FrepError::Empty("the bounding boxes of the operands do not overlap".into())
    })?;
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    if !(longest > 0.0 && longest.is_finite()) {
        return Err(FrepError::Empty(format!(
            "the solid's box {:?}..{:?} has no extent",
            b.min, b.max
        )));
    }
    Ok(b.inflated(3.0 * longest / resolution.max(1) as f64))
}

/// Mesh `solid` (see the module doc). An empty result (nothing inside) is [`FrepError::Empty`].
pub fn mesh_solid(
    solid: &Solid,
    expression: &str,
    params: &CsgParams,
    progress: &dyn Progress,
) -> Result<(TriMesh, CsgReport), FrepError> {
    let t = Instant::now();
    let domain = meshing_domain(solid, params.resolution)?;
    let frame = Normalization::from_aabb(&domain);
    let unit = Aabb {
        min: frame.forward(&domain.min),
        max: frame.forward(&domain.max),
    };
    // Refinement decides fixed-sign operands once per box of 8 cells.
    let field = SolidField {
        solid,
        frame,
        lattice: 8.0 / params.resolution as f64,
        cache: Default::default(),
    };
    let pp = PolygonizeParams {
        resolution: params.resolution,
        max_cells: params.max_cells,
        refine_steps: params.refine_steps,
        // Modelled solids may hold small pieces on purpose (a bead, a thin ring): sample every
        // tile the solid's bound lets through rather than seed from sign changes only.
        seeding: Seeding::EveryTile,
    };
    let (mut mesh, stats) = polygonize_in(&field, &unit, &pp, &Everywhere, progress)?;
    if mesh.triangles.is_empty() {
        return Err(FrepError::Empty(format!(
            "no surface in {:?}..{:?} at {} cells (e.g. the intersection of disjoint solids)",
            domain.min, domain.max, params.resolution
        )));
    }
    for v in &mut mesh.vertices {
        *v = frame.inverse(v);
    }
    crate::mesh::optimize::optimize_for_gpu(&mut mesh).map_err(|e| {
        FrepError::Io(crate::io::IoError::Encode {
            format: "mesh",
            message: e.to_string(),
        })
    })?;
    let topology = crate::mesh::topology::analyze(&mesh);
    let report = CsgReport {
        expression: expression.to_string(),
        domain: [domain.min, domain.max],
        resolution: params.resolution,
        cell_size: 1.0 / frame.scale / params.resolution as f64,
        blocks_total: stats.blocks_total,
        blocks_active: stats.blocks_active,
        field_evaluations: stats.field_evaluations,
        mesh: topology,
        timings_s: CsgTimings {
            mesh: t.elapsed().as_secs_f64(),
            ..Default::default()
        },
    };
    Ok((mesh, report))
}
