//! Merge the regions' mesh pieces into one mesh: vertices on a seam between two regions were
//! computed bit for bit alike on both sides (see [`super::tasks`]), so welding by exact position
//! joins the pieces without cracks; every other vertex lies on one region's edges only.

use crate::geometry::{Aabb, Point3, TriMesh};
use std::collections::HashMap;

/// Appends `piece` (region `region`'s mesh, whose box is `bx`) to `mesh`. Only the vertices on
/// the box's faces can be shared with another region (a vertex on a grid edge inside a face has
/// that face's coordinate exactly: both ends of its edge have it); each is welded to an equal
/// position from another region already in `mesh` (`seen`: position bits → (vertex, region)).
/// Vertices of one piece are never merged with each other, so no triangle degenerates.
pub(crate) fn append_piece(
    mesh: &mut TriMesh,
    seen: &mut HashMap<[u64; 3], (u32, usize)>,
    piece: TriMesh,
    region: usize,
    bx: &Aabb,
) {
    let on_face = |p: &Point3| (0..3).any(|k| p[k] == bx.min[k] || p[k] == bx.max[k]);
    let push = |mesh: &mut TriMesh, k: usize| {
        mesh.vertices.push(piece.vertices[k]);
        if let Some(n) = piece.normals.get(k) {
            mesh.normals.push(*n);
        }
        (mesh.vertices.len() - 1) as u32
    };
    let remap: Vec<u32> = (0..piece.vertices.len())
        .map(|k| {
            let p = piece.vertices[k];
            if !on_face(&p) {
                return push(mesh, k);
            }
            match seen.get(&p.map(f64::to_bits)) {
                Some(&(v, from)) if from != region => v,
                Some(_) => push(mesh, k),
                None => {
                    let v = push(mesh, k);
                    seen.insert(p.map(f64::to_bits), (v, region));
                    v
                }
            }
        })
        .collect();
    mesh.triangles
        .extend((piece.triangles.iter()).map(|t| t.map(|v| remap[v as usize])));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_sharing_an_edge_weld_into_one_mesh() {
        let a = TriMesh {
            vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            triangles: vec![[0, 1, 2]],
            colors: Vec::new(),
        };
        let b = TriMesh {
            vertices: vec![[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            triangles: vec![[0, 1, 2]],
            colors: Vec::new(),
        };
        // Both pieces' vertices at (1, 0, 0) and (0, 1, 0) lie on faces of their boxes.
        let a_box = Aabb {
            min: [0.0, 0.0, -1.0],
            max: [1.0, 1.0, 1.0],
        };
        let b_box = Aabb {
            min: [1.0, 0.0, -1.0],
            max: [2.0, 1.0, 1.0],
        };
        let (mut m, mut seen) = (TriMesh::default(), HashMap::new());
        append_piece(&mut m, &mut seen, a.clone(), 0, &a_box);
        append_piece(&mut m, &mut seen, b, 1, &b_box);
        assert_eq!(m.vertices.len(), 4, "{:?}", m.vertices);
        assert_eq!(m.normals.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [3, 2, 1]]);
        // Two vertices of one piece at the same position stay apart.
        let mut twice = a;
        twice.vertices[2] = twice.vertices[1];
        let (mut m, mut seen) = (TriMesh::default(), HashMap::new());
        append_piece(&mut m, &mut seen, twice, 0, &a_box);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
    }
}
