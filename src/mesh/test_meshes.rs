//! Small hand-built meshes shared by the mesh and polygonize tests (test builds only).

use crate::geometry::TriMesh;

/// The unit right tetrahedron `(0,0,0), e_x, e_y, e_z`, wound outward.
pub(crate) fn tetrahedron() -> TriMesh {
    TriMesh {
        vertices: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        normals: vec![],
        triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        colors: Vec::new(),
    }
}

/// A sheet of unit squares in z = 0, two triangles each, over the cells `(i, j)` of an
/// `nx × ny` grid for which `keep` holds.
pub(crate) fn sheet(nx: u32, ny: u32, keep: impl Fn(u32, u32) -> bool) -> TriMesh {
    let mut vertices = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            vertices.push([i as f64, j as f64, 0.0]);
        }
    }
    let at = |i: u32, j: u32| j * (nx + 1) + i;
    let mut triangles = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            if keep(i, j) {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
    }
    TriMesh {
        vertices,
        normals: vec![],
        triangles,
        colors: Vec::new(),
    }
}

/// Three triangles on the edge `(0, 1)` (a non-manifold edge): a fin.
pub(crate) fn fin() -> TriMesh {
    TriMesh {
        vertices: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1.0, 0.0],
            [0.5, -1.0, 0.0],
            [0.5, 0.0, 1.0],
        ],
        normals: vec![],
        triangles: vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
        colors: Vec::new(),
    }
}

/// Axis-aligned cube with lower corner `min` and edge `size`: 8 vertices (index `x + 2y + 4z`),
/// 12 triangles wound outward.
pub(crate) fn cube(min: [f64; 3], size: f64) -> TriMesh {
    let vertices = (0..8)
        .map(|i| {
            [
                min[0] + size * (i & 1) as f64,
                min[1] + size * ((i >> 1) & 1) as f64,
                min[2] + size * ((i >> 2) & 1) as f64,
            ]
        })
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let triangles = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    TriMesh {
        vertices,
        normals: vec![],
        triangles,
        colors: Vec::new(),
    }
}

/// Torus around the z axis (major radius `big`, minor `small`) as an `n × m` quad grid, wound outward.
pub(crate) fn torus(big: f64, small: f64, n: u32, m: u32) -> TriMesh {
    let tau = std::f64::consts::TAU;
    let mut vertices = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (tau * i as f64 / n as f64, tau * j as f64 / m as f64);
            let rho = big + small * v.cos();
            vertices.push([rho * u.cos(), rho * u.sin(), small * v.sin()]);
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + (j % m);
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let q = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
            triangles.push([q[0], q[1], q[2]]);
            triangles.push([q[0], q[2], q[3]]);
        }
    }
    TriMesh {
        vertices,
        normals: vec![],
        triangles,
        colors: Vec::new(),
    }
}

/// Disjoint union of two meshes (indices of `b` shifted).
pub(crate) fn merge(a: &TriMesh, b: &TriMesh) -> TriMesh {
    let shift = a.vertices.len() as u32;
    let mut out = a.clone();
    out.vertices.extend_from_slice(&b.vertices);
    out.normals.extend_from_slice(&b.normals);
    out.triangles.extend(
        b.triangles
            .iter()
            .map(|t| [t[0] + shift, t[1] + shift, t[2] + shift]),
    );
    out
}
