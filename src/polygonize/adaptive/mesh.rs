//! The adaptive extractor's last step: marching tetrahedra on the followed cubes and the
//! vertices placed on their tetrahedron edges.

use std::collections::{BTreeMap, HashSet};

use rayon::prelude::*;

use super::super::refine::{EdgeRoot, place_vertices};
use super::super::tets::{self, CrossedEdge, Node};
use super::super::{PolygonizeError, ScalarField};
use super::edge_split;
use super::lattice::{FastMap, Lattice, Samples};
use crate::geometry::{Point3, TriMesh};

/// Triangles as crossed edges, cubes in id order.
pub(super) type EdgeTriangles = Vec<[CrossedEdge; 3]>;

/// Step 3: the triangles of every followed cube, and the crossed edges (ascending by node ids).
pub(super) fn triangulate<'a>(
    field: &'a dyn ScalarField,
    lat: &Lattice,
    samples: &mut Samples<'a>,
    cubes: &BTreeMap<u64, bool>,
) -> (EdgeTriangles, Vec<CrossedEdge>) {
    let split: HashSet<u64> = (cubes.iter()).filter(|c| *c.1).map(|c| *c.0).collect();
    let list: Vec<(u64, bool)> = cubes.iter().map(|(&k, &v)| (k, v)).collect();
    let tets_of = |&(id, is_split): &(u64, bool), out: &mut Vec<[Node; 4]>| {
        let o = lat.cube_of(id).map(|x| 2 * x);
        if is_split {
            tets::split_cube(o, out);
        } else {
            let se = |a: Node, b: Node| edge_split(lat, &split, a, b);
            tets::cone_cube(o, &se, out);
        }
    };
    // Every node the tetrahedra use was evaluated while following; a node left over (none is
    // expected) is evaluated and the pass redone.
    let march_all = |vals: &FastMap<f64>| -> (EdgeTriangles, Vec<Node>) {
        let parts: Vec<(EdgeTriangles, Vec<Node>)> = (list.par_chunks(512))
            .map(|chunk| {
                let (mut tets, mut out, mut missing) = (Vec::new(), Vec::new(), Vec::new());
                for c in chunk {
                    tets.clear();
                    tets_of(c, &mut tets);
                    for t in &tets {
                        match t.map(|n| vals.get(&lat.id(n)).copied()) {
                            [Some(a), Some(b), Some(c), Some(d)] => {
                                tets::march(t, [a, b, c, d], &mut out)
                            }
                            _ => missing
                                .extend(t.iter().filter(|n| !vals.contains_key(&lat.id(**n)))),
                        }
                    }
                }
                (out, missing)
            })
            .collect();
        let (t, m): (Vec<_>, Vec<_>) = parts.into_iter().unzip();
        (t.concat(), m.concat())
    };
    let (mut triangles, missing) = march_all(&samples.values);
    debug_assert!(missing.is_empty(), "{} nodes not evaluated", missing.len());
    if !missing.is_empty() {
        samples.evaluate(field, lat, &missing, false);
        triangles = march_all(&samples.values).0;
    }
    let mut edges: Vec<CrossedEdge> = triangles.iter().flatten().copied().collect();
    edges.par_sort_unstable_by_key(|e| (lat.id(e.0), lat.id(e.1)));
    edges.dedup();
    (triangles, edges)
}

/// One tile's placed vertices: their edge indices, positions, normals, field values spent.
type Placed = (Vec<usize>, Vec<Point3>, Vec<Point3>, u64);

/// Places a vertex on every crossed edge (grouped by tile, on the tile's prepared field) and builds
/// the mesh, vertices in edge order.
pub(super) fn place<'a>(
    field: &'a dyn ScalarField,
    lat: &Lattice,
    samples: &mut Samples<'a>,
    triangles: &EdgeTriangles,
    edges: Vec<CrossedEdge>,
    steps: usize,
) -> Result<TriMesh, PolygonizeError> {
    if edges.len() > u32::MAX as usize {
        return Err(PolygonizeError::TooManyVertices {
            vertices: edges.len(),
        });
    }
    let mut groups: BTreeMap<[i64; 3], Vec<usize>> = BTreeMap::new();
    for (i, e) in edges.iter().enumerate() {
        let mid = [0, 1, 2].map(|k| (e.0[k] + e.1[k]) / 2);
        groups.entry(lat.tile_of(mid)).or_default().push(i);
    }
    let mut work = samples.take(field, lat, groups);
    let s = &samples.values;
    let value = |n: Node| s[&lat.id(n)];
    let placed: Vec<Placed> = work
        .par_iter_mut()
        .map(|(_, prepared, idx)| {
            let roots: Vec<EdgeRoot> = (idx.iter())
                .map(|&i| {
                    let (a, o) = edges[i];
                    EdgeRoot {
                        p_in: lat.point(a),
                        f_in: value(a),
                        p_out: lat.point(o),
                        f_out: value(o),
                        tile: 0,
                    }
                })
                .collect();
            let (p, n, e) = place_vertices(&mut **prepared, &roots, steps);
            (std::mem::take(idx), p, n, e)
        })
        .collect();
    samples.give_back(work);
    let mut mesh = TriMesh {
        vertices: vec![[0.0; 3]; edges.len()],
        normals: vec![[0.0; 3]; edges.len()],
        ..TriMesh::default()
    };
    for (idx, p, n, e) in placed {
        samples.evaluations += e;
        for ((i, p), n) in idx.into_iter().zip(p).zip(n) {
            mesh.vertices[i] = p;
            mesh.normals[i] = n;
        }
    }
    let index = |e: &CrossedEdge| {
        let key = (lat.id(e.0), lat.id(e.1));
        edges
            .binary_search_by_key(&key, |x| (lat.id(x.0), lat.id(x.1)))
            .unwrap() as u32
    };
    mesh.triangles = triangles.par_iter().map(|t| t.map(|e| index(&e))).collect();
    Ok(mesh)
}
