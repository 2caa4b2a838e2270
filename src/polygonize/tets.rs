//! The conforming two-level tetrahedral mesh of the adaptive extractor ([`super::adaptive`]) and
//! marching tetrahedra on any of its tetrahedra.
//!
//! Nodes are points of the fine lattice (integer coordinates, cell `h`); a coarse cube spans 2 fine
//! cells per axis, from fine node `2c`. A **split** cube is cut into its 8 sub-cubes, each split
//! into 6 Kuhn tetrahedra along its diagonal from the coarse corner to the coarse centre (the
//! Kuhn split mirrored in each octant). Every face of such a sub-cube is cut by the diagonal
//! through the coarse corner or the coarse centre, so two sub-cubes of one cube meet on the same
//! diagonal, and a face of the coarse cube is cut into the 8 triangles of a fan around its centre.
//!
//! An **unsplit** cube is the cone from its centre over its 6 faces. A face is the fan around its
//! centre over its 4 corners and the midpoints of its split edges when one of its edges is split
//! (an edge is split when one of the up to 4 cubes around it is split), else the 2 triangles
//! through its lowest and highest corners. Both cubes beside a face see the same split edges, so
//! they cut it alike; beside a split cube all 4 edges are split and the fan is the split cube's.
//! So the tetrahedra of any set of cubes, each split or not, form a simplicial complex (no
//! hanging node, no crack), and marching tetrahedra on it is closed, manifold and consistently
//! oriented wherever the zero set stays inside the cubes (Doi & Koide 1991 on one level).

use super::kuhn::ORDERS;

/// A fine-lattice node (integer coordinates).
pub(crate) type Node = [i64; 3];

/// The 4 cubes (coarse indices, some maybe outside the lattice) around the coarse edge between
/// nodes `a` and `b` (even coordinates, one axis apart); `None` when `a == b`.
pub(crate) fn cubes_around_edge(a: Node, b: Node) -> Option<[[i64; 3]; 4]> {
    let axis = (0..3).find(|&k| a[k] != b[k])?;
    let lo = [0, 1, 2].map(|k| a[k].min(b[k]) / 2);
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    Some([(0, 0), (1, 0), (0, 1), (1, 1)].map(|(du, dv)| {
        let mut c = lo;
        c[u] -= du;
        c[v] -= dv;
        c
    }))
}

/// The 48 tetrahedra of split cube `o` (its lowest fine node, even coordinates).
pub(crate) fn split_cube(o: Node, out: &mut Vec<[Node; 4]>) {
    let centre = o.map(|x| x + 1);
    for oct in 0..8 {
        let v0: Node = [0, 1, 2].map(|k| o[k] + 2 * ((oct >> k) & 1));
        let step: Node = [0, 1, 2].map(|k| if (oct >> k) & 1 == 0 { 1 } else { -1 });
        for [a, b, _] in ORDERS {
            let mut p1 = v0;
            p1[a] += step[a];
            let mut p2 = p1;
            p2[b] += step[b];
            out.push([v0, p1, p2, centre]);
        }
    }
}

/// The tetrahedra of unsplit cube `o` (lowest fine node, even coordinates): the cone from its
/// centre over its faces; `split_edge(a, b)` says whether the coarse edge between corners `a` and
/// `b` is split.
pub(crate) fn cone_cube(
    o: Node,
    split_edge: &dyn Fn(Node, Node) -> bool,
    out: &mut Vec<[Node; 4]>,
) {
    let centre = o.map(|x| x + 1);
    let mut tris = Vec::with_capacity(8);
    for axis in 0..3 {
        for side in [0, 2] {
            tris.clear();
            face_triangles(o, axis, side, split_edge, &mut tris);
            out.extend(tris.iter().map(|t| [t[0], t[1], t[2], centre]));
        }
    }
}

/// The boundary of the face of cube `o` normal to `axis` at offset `side` (0 or 2) as the cubes
/// beside it cut it: its corners in cyclic order with the midpoints of its split edges between
/// them, and its centre when one of its edges is split (the fan's apex), else `None`.
pub(crate) fn face_ring(
    o: Node,
    axis: usize,
    side: i64,
    split_edge: &dyn Fn(Node, Node) -> bool,
) -> (Vec<Node>, Option<Node>) {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let at = |du: i64, dv: i64| {
        let mut p = o;
        p[axis] += side;
        p[u] += du;
        p[v] += dv;
        p
    };
    let q = [at(0, 0), at(2, 0), at(2, 2), at(0, 2)];
    let mut ring = Vec::with_capacity(8);
    for i in 0..4 {
        let (a, b) = (q[i], q[(i + 1) % 4]);
        ring.push(a);
        if split_edge(a, b) {
            ring.push([0, 1, 2].map(|k| (a[k] + b[k]) / 2));
        }
    }
    let centre = (ring.len() > 4).then(|| at(1, 1));
    (ring, centre)
}

/// The triangles of the face of cube `o` normal to `axis` at offset `side` (0 or 2), as
/// [`cone_cube`] cuts it: the fan around its centre over [`face_ring`], or the 2 triangles through
/// its lowest and highest corners when no edge is split.
fn face_triangles(
    o: Node,
    axis: usize,
    side: i64,
    split_edge: &dyn Fn(Node, Node) -> bool,
    tris: &mut Vec<[Node; 3]>,
) {
    let (ring, centre) = face_ring(o, axis, side, split_edge);
    match centre {
        None => {
            tris.push([ring[0], ring[1], ring[2]]);
            tris.push([ring[0], ring[2], ring[3]]);
        }
        Some(fc) => {
            for i in 0..ring.len() {
                tris.push([fc, ring[i], ring[(i + 1) % ring.len()]]);
            }
        }
    }
}

/// A tetrahedron edge crossing the zero set: its inside end first (`f < 0`), then its outside end.
pub(crate) type CrossedEdge = (Node, Node);

/// Marching tetrahedra on one tetrahedron with node values `f` (inside: `f < 0`; zero and NaN
/// outside): 0, 1 or 2 triangles as crossed edges, counter-clockwise seen from the outside.
pub(crate) fn march(tet: &[Node; 4], f: [f64; 4], out: &mut Vec<[CrossedEdge; 3]>) {
    let inside: Vec<usize> = (0..4).filter(|&i| is_inside(f[i])).collect();
    let outside: Vec<usize> = (0..4).filter(|&i| !is_inside(f[i])).collect();
    let e = |i: usize, o: usize| (tet[i], tet[o]);
    let mut tris: Vec<[CrossedEdge; 3]> = match (inside.as_slice(), outside.as_slice()) {
        ([i], [a, b, c]) => vec![[e(*i, *a), e(*i, *b), e(*i, *c)]],
        ([a, b, c], [o]) => vec![[e(*a, *o), e(*b, *o), e(*c, *o)]],
        ([i0, i1], [o0, o1]) => {
            let q = [e(*i0, *o0), e(*i0, *o1), e(*i1, *o1), e(*i1, *o0)];
            vec![[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        }
        _ => return,
    };
    // Direction from the inside nodes' centroid to the outside nodes' centroid (scaled).
    let (ni, no) = (inside.len() as i64, outside.len() as i64);
    let mut d = [0i64; 3];
    for i in 0..4 {
        let w = if is_inside(f[i]) { -no } else { ni };
        (0..3).for_each(|k| d[k] += w * tet[i][k]);
    }
    for t in &mut tris {
        if winding(t, d) < 0 {
            t.swap(1, 2);
        }
    }
    out.extend(tris);
}

/// Inside test: `f < 0` (zero and NaN are outside).
fn is_inside(f: f64) -> bool {
    f < 0.0
}

/// `(b − a) × (c − a) · d` on the doubled edge midpoints of triangle `t`.
fn winding(t: &[CrossedEdge; 3], d: [i64; 3]) -> i64 {
    let m = |e: &CrossedEdge| [0, 1, 2].map(|k| e.0[k] + e.1[k]);
    let [a, b, c] = [m(&t[0]), m(&t[1]), m(&t[2])];
    let u = [0, 1, 2].map(|k| b[k] - a[k]);
    let v = [0, 1, 2].map(|k| c[k] - a[k]);
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn volume6(t: &[Node; 4]) -> i64 {
        let [p0, p1, p2, p3] = *t;
        let u = [0, 1, 2].map(|k| p1[k] - p0[k]);
        let v = [0, 1, 2].map(|k| p2[k] - p0[k]);
        let w = [0, 1, 2].map(|k| p3[k] - p0[k]);
        (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]))
            .abs()
    }

    /// Every triangle face of the tetrahedra, sorted, with the number of tetrahedra holding it.
    fn faces(tets: &[[Node; 4]]) -> HashMap<[Node; 3], usize> {
        let mut m = HashMap::new();
        for t in tets {
            for skip in 0..4 {
                let mut f: Vec<Node> = (0..4).filter(|&i| i != skip).map(|i| t[i]).collect();
                f.sort();
                *m.entry([f[0], f[1], f[2]]).or_insert(0) += 1;
            }
        }
        m
    }

    #[test]
    fn mixed_cubes_form_a_conforming_complex() {
        // A 3 × 3 × 3 block of cubes, some split: the tetrahedra fill it exactly (volume), and
        // every inner triangle is shared by exactly two tetrahedra, every outer one lies on the
        // block's boundary (a hanging node or a crack would leave inner faces used once).
        for pattern in [
            0u32,
            1,
            0b1_0000_0000_0000,
            0b101_0010_0100_0000_1001_0001,
            !0,
        ] {
            let split = |c: [i64; 3]| {
                let i = c[0] + 3 * (c[1] + 3 * c[2]);
                (0..27).contains(&i)
                    && c.iter().all(|x| (0..3).contains(x))
                    && pattern >> i & 1 == 1
            };
            let split_edge =
                |a: Node, b: Node| cubes_around_edge(a, b).unwrap().into_iter().any(split);
            let mut tets = Vec::new();
            for z in 0..3 {
                for y in 0..3 {
                    for x in 0..3 {
                        let o = [2 * x, 2 * y, 2 * z];
                        if split([x, y, z]) {
                            split_cube(o, &mut tets);
                        } else {
                            cone_cube(o, &split_edge, &mut tets);
                        }
                    }
                }
            }
            let vol: i64 = tets.iter().map(volume6).sum();
            assert_eq!(vol, 6 * 6 * 6 * 6, "pattern {pattern:b}");
            assert!(tets.iter().all(|t| volume6(t) > 0));
            for (f, n) in faces(&tets) {
                let on_boundary = (0..3).any(|k| {
                    f.iter()
                        .all(|p| p[k] == f[0][k] && (p[k] == 0 || p[k] == 6))
                });
                assert_eq!(
                    n,
                    if on_boundary { 1 } else { 2 },
                    "face {f:?} pattern {pattern:b}"
                );
            }
        }
    }

    #[test]
    fn marching_a_tetrahedron_winds_towards_the_outside() {
        let tet = [[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]];
        let mut out = Vec::new();
        march(&tet, [-1.0, 1.0, 1.0, 1.0], &mut out);
        assert_eq!(out.len(), 1);
        // Outward = away from the origin: normal · (1,1,1) > 0.
        assert!(winding(&out[0], [1, 1, 1]) > 0);
        out.clear();
        march(&tet, [1.0, -1.0, -1.0, -1.0], &mut out);
        assert!(winding(&out[0], [-1, -1, -1]) > 0);
        out.clear();
        march(&tet, [-1.0, -1.0, 1.0, 1.0], &mut out);
        assert_eq!(out.len(), 2);
        march(&tet, [1.0, 0.0, 1.0, f64::NAN], &mut out);
        assert_eq!(out.len(), 2);
    }
}
