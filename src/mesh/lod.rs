//! Levels of detail: error-bounded edge-collapse simplification (meshoptimizer's `simplify`, a
//! quadric-error collapser after Garland & Heckbert 1997) of a triangle mesh, coarser level by
//! level. Level `k` aims at a quarter of the triangles of level `k − 1` and stops earlier when the
//! next collapse would move the surface farther than its error bound, `k` times
//! [`LOD_ERROR_REL`] of the bounding-box diagonal. Border vertices (open scans) stay in place.
//! Each level keeps the original vertices it uses (positions, normals, colours), so levels nest.
//!
//! Time O(F log F) per level, memory O(V + F).

use crate::geometry::{Aabb, TriMesh};

/// Error bound of level 1, as a fraction of the bounding-box diagonal (level k: k times this).
pub const LOD_ERROR_REL: f64 = 2e-3;

/// One simplified level.
#[derive(Debug, Clone, PartialEq)]
pub struct Lod {
    /// The simplified mesh (a subset of the input's vertices, renumbered).
    pub mesh: TriMesh,
    /// The simplifier's error estimate: the largest distance a collapse moved the surface, in the
    /// mesh's units.
    pub error: f64,
    /// [`Lod::error`] divided by the bounding-box diagonal.
    pub error_rel: f64,
}

/// `levels` simplified versions of `mesh`, coarse after fine (level 1 first). A level that cannot
/// simplify further within its bound repeats the previous one's triangle count; an empty mesh
/// gives no levels.
pub fn simplify_levels(mesh: &TriMesh, levels: usize) -> Vec<Lod> {
    if mesh.triangles.is_empty() || mesh.vertices.is_empty() {
        return Vec::new();
    }
    let b = Aabb::from_points(&mesh.vertices);
    let c = b.center();
    let diag = b.diagonal().max(f64::MIN_POSITIVE);
    // Positions relative to the box centre: f32 keeps the object's precision far from the origin.
    let local: Vec<[f32; 3]> = (mesh.vertices.iter())
        .map(|p| [0, 1, 2].map(|k| (p[k] - c[k]) as f32))
        .collect();
    let mut indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let mut out = Vec::with_capacity(levels);
    for k in 1..=levels {
        let bound = LOD_ERROR_REL * k as f64 * diag;
        let target = (indices.len() / 4 / 3 * 3).max(3);
        let mut err = 0f32;
        let options =
            meshopt::SimplifyOptions::LockBorder | meshopt::SimplifyOptions::ErrorAbsolute;
        let next = meshopt::simplify_decoder(
            &indices,
            &local,
            target,
            bound as f32,
            options,
            Some(&mut err),
        );
        if !next.is_empty() {
            indices = next;
        }
        let error = f64::from(err).max(out.last().map_or(0.0, |l: &Lod| l.error));
        out.push(Lod {
            mesh: compact(mesh, &indices),
            error,
            error_rel: error / diag,
        });
    }
    out
}

/// The triangles `indices` (into `mesh`'s vertices) as a mesh of only the vertices they use.
fn compact(mesh: &TriMesh, indices: &[u32]) -> TriMesh {
    let mut new_id = vec![u32::MAX; mesh.vertices.len()];
    let mut used: Vec<usize> = Vec::new();
    let mut map = |v: u32| {
        let slot = &mut new_id[v as usize];
        if *slot == u32::MAX {
            *slot = used.len() as u32;
            used.push(v as usize);
        }
        *slot
    };
    let triangles: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|t| [map(t[0]), map(t[1]), map(t[2])])
        .collect();
    TriMesh {
        vertices: used.iter().map(|&v| mesh.vertices[v]).collect(),
        normals: match mesh.normals.len() == mesh.vertices.len() {
            true => used.iter().map(|&v| mesh.normals[v]).collect(),
            false => Vec::new(),
        },
        colors: match mesh.colors.len() == mesh.vertices.len() {
            true => used.iter().map(|&v| mesh.colors[v]).collect(),
            false => Vec::new(),
        },
        triangles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::Shape;

    #[test]
    fn levels_shrink_within_their_bounds_and_stay_closed() {
        let mesh = Shape::by_name("sphere").unwrap().truth_mesh(128);
        let levels = simplify_levels(&mesh, 3);
        assert_eq!(levels.len(), 3);
        let mut prev = mesh.triangles.len();
        for (k, l) in levels.iter().enumerate() {
            let t = l.mesh.triangles.len();
            assert!(
                t < prev,
                "level {} has {t} triangles, not fewer than {prev}",
                k + 1
            );
            assert!(
                l.error_rel <= LOD_ERROR_REL * (k + 1) as f64 + 1e-9,
                "{}",
                l.error_rel
            );
            let topo = crate::mesh::analyze(&l.mesh);
            assert!(topo.watertight && topo.manifold, "{topo:?}");
            assert_eq!(l.mesh.normals.len(), l.mesh.vertices.len());
            // Every vertex is an input vertex (levels nest).
            for p in &l.mesh.vertices {
                assert!(mesh.vertices.contains(p), "{p:?}");
            }
            prev = t;
        }
    }
}
