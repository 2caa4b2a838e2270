//! Vertex and triangle neighbourhoods of a closed mesh, and the cut test of a loop.

use rayon::prelude::*;

use crate::geometry::TriMesh;

/// Vertex and triangle neighbourhoods of a closed, manifold, oriented mesh.
pub(super) struct Adjacency {
    /// The mesh's triangles (corners of each).
    pub(super) tris: Vec<[u32; 3]>,
    /// Neighbours of each vertex, CSR (`vstart`, `vlist`).
    vstart: Vec<u32>,
    vlist: Vec<u32>,
    /// Triangles at each vertex, CSR (`tstart`, `tlist`).
    tstart: Vec<u32>,
    tlist: Vec<u32>,
    /// The triangle across edge `k` (corner `k` to corner `k + 1`) of each triangle.
    pub(super) across: Vec<[u32; 3]>,
}

impl Adjacency {
    /// `None` unless every edge has exactly two triangles that traverse it in opposite directions.
    pub(super) fn new(mesh: &TriMesh) -> Option<Adjacency> {
        let n = mesh.vertices.len();
        let tris = mesh.triangles.clone();
        let mut half: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(3 * tris.len());
        for (t, tri) in tris.iter().enumerate() {
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return None;
            }
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                half.push((a.min(b), a.max(b), t as u32, k as u8));
            }
        }
        half.par_sort_unstable();
        if half
            .windows(3)
            .any(|w| (w[0].0, w[0].1) == (w[2].0, w[2].1))
        {
            return None; // an edge of three or more triangles
        }
        let mut across = vec![[u32::MAX; 3]; tris.len()];
        let mut deg = vec![0u32; n + 1];
        for pair in half.chunks(2) {
            let [x, y] = pair else { return None };
            if (x.0, x.1) != (y.0, y.1) || x.2 == y.2 {
                return None; // a border edge
            }
            if tris[x.2 as usize][x.3 as usize] == tris[y.2 as usize][y.3 as usize] {
                return None; // both traverse it the same way: not oriented
            }
            across[x.2 as usize][x.3 as usize] = y.2;
            across[y.2 as usize][y.3 as usize] = x.2;
            deg[x.0 as usize] += 1;
            deg[x.1 as usize] += 1;
        }
        let vstart = prefix(&deg);
        let mut fill = vstart.clone();
        let mut vlist = vec![0u32; vstart[n] as usize];
        for pair in half.chunks(2) {
            let (a, b) = (pair[0].0, pair[0].1);
            vlist[fill[a as usize] as usize] = b;
            fill[a as usize] += 1;
            vlist[fill[b as usize] as usize] = a;
            fill[b as usize] += 1;
        }
        let mut tdeg = vec![0u32; n + 1];
        tris.iter().flatten().for_each(|&v| tdeg[v as usize] += 1);
        let tstart = prefix(&tdeg);
        let mut fill = tstart.clone();
        let mut tlist = vec![0u32; 3 * tris.len()];
        for (t, tri) in tris.iter().enumerate() {
            for &v in tri {
                tlist[fill[v as usize] as usize] = t as u32;
                fill[v as usize] += 1;
            }
        }
        Some(Adjacency {
            tris,
            vstart,
            vlist,
            tstart,
            tlist,
            across,
        })
    }

    pub(super) fn neighbours(&self, v: u32) -> &[u32] {
        &self.vlist[self.vstart[v as usize] as usize..self.vstart[v as usize + 1] as usize]
    }

    pub(super) fn triangles_at(&self, v: u32) -> &[u32] {
        &self.tlist[self.tstart[v as usize] as usize..self.tstart[v as usize + 1] as usize]
    }

    /// Edge `k` of triangle `t` as a sorted pair.
    pub(super) fn edge(&self, t: u32, k: usize) -> (u32, u32) {
        let tri = self.tris[t as usize];
        let (a, b) = (tri[k], tri[(k + 1) % 3]);
        (a.min(b), a.max(b))
    }

    /// The two triangles on edge `a`–`b`.
    pub(super) fn sides(&self, a: u32, b: u32) -> Option<(u32, u32)> {
        let e = (a.min(b), a.max(b));
        self.triangles_at(a).iter().find_map(|&t| {
            let k = (0..3).find(|&k| self.edge(t, k) == e)?;
            Some((t, self.across[t as usize][k]))
        })
    }

    /// Whether the triangles stay connected when no step crosses an edge of the closed path
    /// `cycle`: true exactly when the loop does not separate the surface (a handle loop). Searches
    /// from both sides in turn and stops when one side runs out (separating: about twice the cost
    /// of the smaller side) or the two meet.
    pub(super) fn non_separating(&self, cycle: &[u32]) -> bool {
        let m = cycle.len();
        let mut cut: Vec<(u32, u32)> = (0..m)
            .map(|i| {
                let (a, b) = (cycle[i], cycle[(i + 1) % m]);
                (a.min(b), a.max(b))
            })
            .collect();
        cut.sort_unstable();
        let Some((left, right)) = self.sides(cycle[0], cycle[1]) else {
            return false;
        };
        const NONE: u8 = 2;
        let mut side = vec![NONE; self.tris.len()];
        side[left as usize] = 0;
        side[right as usize] = 1;
        let mut fronts = [vec![left], vec![right]];
        loop {
            for s in 0..2u8 {
                let Some(t) = fronts[s as usize].pop() else {
                    return false; // this side is enclosed by the loop
                };
                for k in 0..3 {
                    if cut.binary_search(&self.edge(t, k)).is_ok() {
                        continue;
                    }
                    let u = self.across[t as usize][k] as usize;
                    if side[u] == NONE {
                        side[u] = s;
                        fronts[s as usize].push(u as u32);
                    } else if side[u] != s {
                        return true;
                    }
                }
            }
        }
    }
}

fn prefix(deg: &[u32]) -> Vec<u32> {
    let mut start = vec![0u32; deg.len()];
    for i in 1..deg.len() {
        start[i] = start[i - 1] + deg[i - 1];
    }
    start
}
