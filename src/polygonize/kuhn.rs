//! Marching-tetrahedra case table for the Kuhn (Freudenthal) split of a cube into 6 tetrahedra.
//!
//! Every tetrahedron is a monotone path `0 → e_a → e_a + e_b → (1,1,1)` through the cube's corners, for
//! the 6 orders `(a, b, c)` of the axes (Kuhn 1960; Freudenthal 1942). The same split in every cube is a
//! simplicial complex of space, so shared faces match and the piecewise-linear zero set is a closed
//! 2-manifold wherever no corner value is exactly zero (zero counts as outside). For each tetrahedron and
//! each of the 16 inside/outside patterns the table lists 0, 1 or 2 triangles as cube edges; each triangle
//! is wound so that its normal points from the inside corners to the outside corners, which makes the
//! whole surface consistently oriented. The table is built once per call in `O(1)`.

/// A cube edge: `(lo, dir)` with `lo` the corner bits (`x + 2y + 4z`) of its lower end and `dir` the bits
/// of the step to its upper end (`1..=7`).
pub(crate) type CubeEdge = (u8, u8);

/// The triangles produced by one tetrahedron for one sign pattern.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct TetCase {
    /// Number of triangles used (0, 1 or 2).
    pub count: u8,
    /// Triangles as cube edges, counter-clockwise seen from the outside (positive) side.
    pub tris: [[CubeEdge; 3]; 2],
}

/// The 6 axis orders `(a, b, c)` of the Kuhn split.
pub(crate) const ORDERS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// Corner bits of the 6 Kuhn tetrahedra.
pub(crate) const TETS: [[u8; 4]; 6] = {
    let orders = ORDERS;
    let mut out = [[0u8; 4]; 6];
    let mut t = 0;
    while t < 6 {
        let [a, b, _] = orders[t];
        out[t] = [0, 1 << a, (1 << a) | (1 << b), 7];
        t += 1;
    }
    out
};

/// Integer position (0/1 per axis) of cube corner `bits`.
fn pos(bits: u8) -> [i64; 3] {
    [
        (bits & 1) as i64,
        ((bits >> 1) & 1) as i64,
        ((bits >> 2) & 1) as i64,
    ]
}

/// The cube edge between two corners of one Kuhn tetrahedron (one corner's bits contain the other's).
fn edge(u: u8, v: u8) -> CubeEdge {
    (u & v, u ^ v)
}

/// Doubled midpoint of a cube edge (exact integers).
fn mid2(e: CubeEdge) -> [i64; 3] {
    let (a, b) = (pos(e.0), pos(e.0 | e.1));
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `(b − a) × (c − a) · d` on the doubled midpoints.
fn winding(tri: [CubeEdge; 3], d: [i64; 3]) -> i64 {
    let [a, b, c] = tri.map(mid2);
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
}

/// Scaled direction from the centroid of the inside corners to that of the outside corners.
fn inside_to_outside(tet: [u8; 4], mask: u8) -> [i64; 3] {
    let n_in = mask.count_ones() as i64;
    let mut d = [0i64; 3];
    for (i, &c) in tet.iter().enumerate() {
        let weight = if mask >> i & 1 == 1 {
            -(4 - n_in)
        } else {
            n_in
        };
        let p = pos(c);
        (0..3).for_each(|k| d[k] += weight * p[k]);
    }
    d
}

/// Triangles of tetrahedron `tet` when the corners flagged in `mask` (bit `i` = corner `i`) are inside.
fn tet_case(tet: [u8; 4], mask: u8) -> TetCase {
    let inside: Vec<u8> = (0..4)
        .filter(|&i| mask >> i & 1 == 1)
        .map(|i| tet[i])
        .collect();
    let outside: Vec<u8> = (0..4)
        .filter(|&i| mask >> i & 1 == 0)
        .map(|i| tet[i])
        .collect();
    let d = inside_to_outside(tet, mask);
    let mut case = TetCase::default();
    let mut tris: Vec<[CubeEdge; 3]> = match (inside.as_slice(), outside.as_slice()) {
        ([i], [a, b, c]) | ([a, b, c], [i]) => vec![[edge(*i, *a), edge(*i, *b), edge(*i, *c)]],
        ([i0, i1], [o0, o1]) => {
            let q = [
                edge(*i0, *o0),
                edge(*i0, *o1),
                edge(*i1, *o1),
                edge(*i1, *o0),
            ];
            vec![[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        }
        _ => vec![],
    };
    for t in &mut tris {
        if winding(*t, d) < 0 {
            t.swap(1, 2);
        }
    }
    case.count = tris.len() as u8;
    for (slot, t) in case.tris.iter_mut().zip(tris) {
        *slot = t;
    }
    case
}

/// The full table: `table[tet][mask]`.
pub(crate) fn case_table() -> [[TetCase; 16]; 6] {
    let mut table = [[TetCase::default(); 16]; 6];
    for (t, row) in table.iter_mut().enumerate() {
        for (mask, case) in row.iter_mut().enumerate() {
            *case = tet_case(TETS[t], mask as u8);
        }
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tetrahedra_fill_the_cube_and_cases_are_oriented() {
        // Each Kuhn tetrahedron has volume 1/6, and together they have volume 1 with no overlap
        // (each is the simplex x_a ≤ x_b ≤ x_c of one axis order).
        let mut volume6 = 0;
        for tet in TETS {
            let [p0, p1, p2, p3] = tet.map(pos);
            let u = [0, 1, 2].map(|k| p1[k] - p0[k]);
            let v = [0, 1, 2].map(|k| p2[k] - p0[k]);
            let w = [0, 1, 2].map(|k| p3[k] - p0[k]);
            let det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
                + u[2] * (v[0] * w[1] - v[1] * w[0]);
            assert_eq!(det.abs(), 1);
            volume6 += det.abs();
        }
        assert_eq!(volume6, 6);
        let table = case_table();
        for (t, row) in table.iter().enumerate() {
            for (mask, case) in row.iter().enumerate() {
                let expected = match (mask as u32).count_ones() {
                    0 | 4 => 0,
                    2 => 2,
                    _ => 1,
                };
                assert_eq!(case.count, expected, "tet {t} mask {mask}");
                let d = inside_to_outside(TETS[t], mask as u8);
                for tri in &case.tris[..case.count as usize] {
                    // Never degenerate, always wound towards the outside corners.
                    assert!(winding(*tri, d) > 0, "tet {t} mask {mask}");
                    for e in tri {
                        assert!(e.1 != 0 && e.0 & e.1 == 0);
                    }
                }
                if case.count == 1 {
                    // The complementary pattern gives the same triangle with opposite winding.
                    let o = row[15 - mask].tris[0];
                    let rev = [o[0], o[2], o[1]];
                    let rotations = [rev, [rev[1], rev[2], rev[0]], [rev[2], rev[0], rev[1]]];
                    assert!(rotations.contains(&case.tris[0]), "tet {t} mask {mask}");
                }
            }
        }
    }
}
