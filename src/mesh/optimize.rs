//! GPU-friendly reordering of a triangle mesh: triangles for the post-transform vertex cache
//! (meshoptimizer's `optimizeVertexCache`, after Forsyth / Sander et al. "Tipsify"), then vertices in
//! first-use order so that fetches stream linearly (what `optimizeVertexFetch` does, applied to both
//! positions and normals). `O(F)` for `F` triangles, plus meshoptimizer's linear-time cache optimizer.
//!
//! The set of triangles (as position triples, with their winding) is unchanged; unused vertices are dropped.

use thiserror::Error;

use crate::geometry::TriMesh;

/// FIFO cache size used to measure the average cache miss ratio.
const CACHE_SIZE: u32 = 16;

/// Vertex-cache efficiency before and after [`optimize_for_gpu`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptimizeStats {
    /// Average cache miss ratio (vertex shader invocations per triangle, 16-entry FIFO) before; 0.5–3.0.
    pub acmr_before: f64,
    /// Average cache miss ratio after the reordering (lower is better).
    pub acmr_after: f64,
    /// Vertices dropped because no triangle referenced them.
    pub unused_vertices_removed: usize,
}

/// Why a mesh could not be reordered.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum OptimizeError {
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "triangle {triangle} refers to vertex {index} but the mesh has only {vertices} vertices; fix the index buffer"
    )]
    IndexOutOfRange {
        /// Triangle number.
        triangle: usize,
        /// The offending vertex index.
        index: u32,
        /// Number of vertices in the mesh.
        vertices: usize,
    },
    /// `normals` is neither empty nor one per vertex.
    #[error(
        "the mesh has {normals} normals for {vertices} vertices; give one normal per vertex or none"
    )]
    NormalCountMismatch {
        /// Number of normals.
        normals: usize,
        /// Number of vertices.
        vertices: usize,
    },
}

/// Reorders `mesh` in place for rendering: triangles for the vertex cache, then vertices (and their
/// normals) in first-use order. Returns the ACMR before and after.
///
/// # Example
/// ```
/// use rbfsurf::geometry::TriMesh;
/// let mut quad = TriMesh {
///     vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
///     normals: vec![],
///     triangles: vec![[0, 1, 2], [0, 2, 3]],
///     colors: vec![],
/// };
/// let stats = rbfsurf::mesh::optimize_for_gpu(&mut quad).unwrap();
/// assert!(stats.acmr_after <= stats.acmr_before);
/// ```
pub fn optimize_for_gpu(mesh: &mut TriMesh) -> Result<OptimizeStats, OptimizeError> {
    let nv = mesh.vertices.len();
    if !mesh.normals.is_empty() && mesh.normals.len() != nv {
        return Err(OptimizeError::NormalCountMismatch {
            normals: mesh.normals.len(),
            vertices: nv,
        });
    }
    for (triangle, t) in mesh.triangles.iter().enumerate() {
        if let Some(&index) = t.iter().find(|&&v| v as usize >= nv) {
            return Err(OptimizeError::IndexOutOfRange {
                triangle,
                index,
                vertices: nv,
            });
        }
    }
    let mut indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    if indices.is_empty() {
        let removed = nv;
        mesh.vertices.clear();
        mesh.normals.clear();
        mesh.colors.clear();
        return Ok(OptimizeStats {
            acmr_before: 0.0,
            acmr_after: 0.0,
            unused_vertices_removed: removed,
        });
    }
    let acmr_before = meshopt::analyze_vertex_cache(&indices, nv, CACHE_SIZE, 0, 0).acmr as f64;
    meshopt::optimize_vertex_cache_in_place(&mut indices, nv);
    let used = reorder_by_first_use(mesh, &mut indices);
    let acmr_after = meshopt::analyze_vertex_cache(&indices, used, CACHE_SIZE, 0, 0).acmr as f64;
    mesh.triangles = indices
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    Ok(OptimizeStats {
        acmr_before,
        acmr_after,
        unused_vertices_removed: nv - used,
    })
}

/// Renumbers vertices in order of first use in `indices` (rewriting `indices`, positions and normals);
/// returns the number of vertices kept.
fn reorder_by_first_use(mesh: &mut TriMesh, indices: &mut [u32]) -> usize {
    let mut remap = vec![u32::MAX; mesh.vertices.len()];
    let mut order: Vec<u32> = Vec::with_capacity(mesh.vertices.len());
    for i in indices.iter_mut() {
        let slot = &mut remap[*i as usize];
        if *slot == u32::MAX {
            *slot = order.len() as u32;
            order.push(*i);
        }
        *i = *slot;
    }
    mesh.vertices = order.iter().map(|&v| mesh.vertices[v as usize]).collect();
    if !mesh.normals.is_empty() {
        mesh.normals = order.iter().map(|&v| mesh.normals[v as usize]).collect();
    }
    if mesh.colors.len() == remap.len() {
        mesh.colors = order.iter().map(|&v| mesh.colors[v as usize]).collect();
    }
    order.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point3;
    use crate::mesh::test_meshes::torus;

    /// Triangles as position triples rotated so the lexicographically smallest corner comes first.
    fn canonical(mesh: &TriMesh) -> Vec<[[u64; 3]; 3]> {
        let key = |p: Point3| p.map(f64::to_bits);
        let mut out: Vec<[[u64; 3]; 3]> = mesh
            .triangles
            .iter()
            .map(|t| {
                let c = t.map(|v| key(mesh.vertices[v as usize]));
                let r = (0..3).min_by_key(|&k| c[k]).unwrap();
                [c[r], c[(r + 1) % 3], c[(r + 2) % 3]]
            })
            .collect();
        out.sort_unstable();
        out
    }

    /// Shuffles the triangle order and the vertex numbering with a seeded splitmix64.
    fn scramble(mesh: &mut TriMesh, seed: u64) {
        let mut s = seed;
        let mut next = move || {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        };
        let n = mesh.vertices.len();
        let mut perm: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            perm.swap(i, next() as usize % (i + 1));
        }
        let mut vertices = vec![[0.0; 3]; n];
        let mut normals = vec![[0.0; 3]; n];
        for (old, &new) in perm.iter().enumerate() {
            vertices[new] = mesh.vertices[old];
            normals[new] = mesh.normals[old];
        }
        mesh.vertices = vertices;
        mesh.normals = normals;
        for t in &mut mesh.triangles {
            *t = t.map(|v| perm[v as usize] as u32);
        }
        for i in (1..mesh.triangles.len()).rev() {
            mesh.triangles.swap(i, next() as usize % (i + 1));
        }
    }

    #[test]
    fn same_triangles_and_better_cache() {
        let mut mesh = torus(2.0, 0.5, 40, 20);
        mesh.normals = mesh
            .vertices
            .iter()
            .map(|p| [p[0], -p[1], 2.0 * p[2]])
            .collect();
        mesh.vertices.push([9.0; 3]);
        mesh.normals.push([0.0; 3]);
        scramble(&mut mesh, 7);
        let before = canonical(&mesh);
        let stats = optimize_for_gpu(&mut mesh).unwrap();
        assert_eq!(canonical(&mesh), before);
        assert_eq!(stats.unused_vertices_removed, 1);
        assert_eq!(mesh.vertices.len(), 800);
        assert!(stats.acmr_after <= stats.acmr_before, "{stats:?}");
        assert!(stats.acmr_after < 0.8, "{stats:?}");
        // Normals still travel with their vertex.
        for (p, n) in mesh.vertices.iter().zip(&mesh.normals) {
            assert_eq!(*n, [p[0], -p[1], 2.0 * p[2]]);
        }
        // First-use order: the index buffer introduces vertices 0, 1, 2, ... in sequence.
        let mut seen = 0;
        for &v in mesh.triangles.iter().flatten() {
            assert!(v <= seen);
            if v == seen {
                seen += 1;
            }
        }
    }

    #[test]
    fn bad_input_is_rejected() {
        let mut mesh = torus(2.0, 0.5, 4, 4);
        mesh.triangles[3][1] = 99;
        assert!(matches!(
            optimize_for_gpu(&mut mesh),
            Err(OptimizeError::IndexOutOfRange {
                triangle: 3,
                index: 99,
                ..
            })
        ));
        let mut mesh = torus(2.0, 0.5, 4, 4);
        mesh.normals = vec![[0.0; 3]; 3];
        assert!(matches!(
            optimize_for_gpu(&mut mesh),
            Err(OptimizeError::NormalCountMismatch { .. })
        ));
    }
}
