//! Geodesic balls around seeds, and the short generator loops of those that are not discs.

use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, HashSet};

use super::{Adjacency, Loop};
use crate::geometry::{TriMesh, dist2};
use crate::mesh::incidence::UnionFind;

/// Per-thread buffers of the geodesic balls.
pub(super) struct Ball {
    dist: Vec<f64>,
    parent: Vec<u32>,
    /// Local index of each triangle inside the ball, or `u32::MAX`.
    local: Vec<u32>,
    /// Vertices reached (to reset `dist`).
    reached: Vec<u32>,
    /// Vertices of the ball.
    pub(super) inside: Vec<u32>,
    /// Triangles of the ball.
    tris: Vec<u32>,
}

/// Min-heap entry.
#[derive(PartialEq)]
struct Entry(f64, u32);
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Most generator loops kept per ball.
const LOOPS_PER_BALL: usize = 8;

impl Ball {
    pub(super) fn new(vertices: usize, triangles: usize) -> Ball {
        Ball {
            dist: vec![f64::INFINITY; vertices],
            parent: vec![u32::MAX; vertices],
            local: vec![u32::MAX; triangles],
            reached: Vec::new(),
            inside: Vec::new(),
            tris: Vec::new(),
        }
    }

    fn reset(&mut self) {
        for &v in &self.reached {
            self.dist[v as usize] = f64::INFINITY;
            self.parent[v as usize] = u32::MAX;
        }
        for &t in &self.tris {
            self.local[t as usize] = u32::MAX;
        }
        self.reached.clear();
        self.inside.clear();
        self.tris.clear();
    }

    fn contains(&self, v: u32, radius: f64) -> bool {
        self.dist[v as usize] <= radius
    }

    /// Grows the geodesic ball of `radius` around `seed` (Dijkstra tree in `parent`) and adds each
    /// vertex just outside whose neighbours are all inside (no pinholes at the ball's rim).
    pub(super) fn grow(&mut self, mesh: &TriMesh, adj: &Adjacency, seed: u32, radius: f64) {
        self.dijkstra(mesh, adj, seed, radius);
        let rim: Vec<u32> = self
            .reached
            .iter()
            .copied()
            .filter(|&w| {
                !self.contains(w, radius)
                    && adj.neighbours(w).iter().all(|&u| self.contains(u, radius))
            })
            .collect();
        for w in rim {
            self.dist[w as usize] = radius; // parent is its nearest inside neighbour already
            self.inside.push(w);
        }
        for &v in &self.inside {
            for &t in adj.triangles_at(v) {
                let tri = adj.tris[t as usize];
                if self.local[t as usize] == u32::MAX
                    && tri.iter().all(|&u| self.contains(u, radius))
                {
                    self.local[t as usize] = self.tris.len() as u32;
                    self.tris.push(t);
                }
            }
        }
    }

    /// The vertices within geodesic distance `radius` of `seed` (in `inside`, tree in `parent`).
    pub(super) fn dijkstra(&mut self, mesh: &TriMesh, adj: &Adjacency, seed: u32, radius: f64) {
        self.dijkstra_from(mesh, adj, &[seed], radius);
    }

    /// The vertices within geodesic distance `radius` of any of `seeds` (in `inside`, a forest in
    /// `parent`).
    pub(super) fn dijkstra_from(
        &mut self,
        mesh: &TriMesh,
        adj: &Adjacency,
        seeds: &[u32],
        radius: f64,
    ) {
        self.reset();
        let p = &mesh.vertices;
        let mut heap = BinaryHeap::new();
        for &seed in seeds {
            if self.dist[seed as usize] > 0.0 {
                self.dist[seed as usize] = 0.0;
                self.reached.push(seed);
                heap.push(Entry(0.0, seed));
            }
        }
        while let Some(Entry(d, v)) = heap.pop() {
            if d > self.dist[v as usize] || d > radius {
                continue;
            }
            self.inside.push(v);
            for &w in adj.neighbours(v) {
                let dw = d + dist2(p[v as usize], p[w as usize]).sqrt();
                if dw < self.dist[w as usize] {
                    if self.dist[w as usize].is_infinite() {
                        self.reached.push(w);
                    }
                    self.dist[w as usize] = dw;
                    self.parent[w as usize] = v;
                    heap.push(Entry(dw, w));
                }
            }
        }
    }

    /// Number of edges with both ends inside.
    fn edges_inside(&self, adj: &Adjacency, radius: f64) -> usize {
        self.inside
            .iter()
            .map(|&u| {
                adj.neighbours(u)
                    .iter()
                    .filter(|&&w| u < w && self.contains(w, radius))
                    .count()
            })
            .sum()
    }

    /// The ball's generator loops (tree–cotree) no longer than `2 · radius`, shortest first.
    pub(super) fn loops(&self, mesh: &TriMesh, adj: &Adjacency, radius: f64) -> Vec<Loop> {
        let chi = self.inside.len() as i64 - self.edges_inside(adj, radius) as i64
            + self.tris.len() as i64;
        if chi >= 1 {
            return Vec::new(); // a disc (or a whole sphere)
        }
        let outside = self.tris.len();
        let mut sets = UnionFind::new(outside + 1);
        // Greedy system of loops (Erickson & Whittlesey 2005): the cotree takes the non-tree edges
        // with the longest fundamental cycles first, so the generators left are the shortest.
        let p = &mesh.vertices;
        let mut non_tree: Vec<(f64, u32, u32)> = Vec::new();
        for &u in &self.inside {
            for &w in adj.neighbours(u) {
                if u > w || !self.contains(w, radius) {
                    continue;
                }
                if self.parent[w as usize] == u || self.parent[u as usize] == w {
                    continue; // a tree edge
                }
                let len = self.dist[u as usize]
                    + self.dist[w as usize]
                    + dist2(p[u as usize], p[w as usize]).sqrt();
                non_tree.push((len, u, w));
            }
        }
        non_tree.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.1, a.2).cmp(&(b.1, b.2))));
        let mut generators = Vec::new();
        for (_, u, w) in non_tree {
            let Some((t0, t1)) = adj.sides(u, w) else {
                continue;
            };
            let id = |t: u32| match self.local[t as usize] {
                u32::MAX => outside as u32,
                l => l,
            };
            if !sets.union(id(t0), id(t1)) {
                generators.push((u, w));
            }
        }
        let mut loops: Vec<Loop> = generators
            .into_iter()
            .filter_map(|(u, w)| self.cycle(mesh, u, w))
            .filter(|c| c.length <= 2.0 * radius)
            .collect();
        loops.sort_by(|a, b| a.length.total_cmp(&b.length));
        loops.truncate(LOOPS_PER_BALL);
        loops
    }

    /// The closed path: tree path from `u` to the common ancestor, back down to `w`, edge `w`–`u`.
    fn cycle(&self, mesh: &TriMesh, u: u32, w: u32) -> Option<Loop> {
        let up = |mut v: u32| {
            let mut path = vec![v];
            while self.parent[v as usize] != u32::MAX {
                v = self.parent[v as usize];
                path.push(v);
            }
            path
        };
        let (pu, pw) = (up(u), up(w));
        let on_pu: HashMap<u32, usize> = pu.iter().enumerate().map(|(i, &v)| (v, i)).collect();
        let (j, iu) = pw
            .iter()
            .enumerate()
            .find_map(|(j, v)| on_pu.get(v).map(|&i| (j, i)))?;
        let mut vertices: Vec<u32> = pu[..=iu].to_vec();
        vertices.extend(pw[..j].iter().rev());
        if vertices.len() < 3 {
            return None;
        }
        let p = &mesh.vertices;
        let m = vertices.len();
        let length = (0..m)
            .map(|i| dist2(p[vertices[i] as usize], p[vertices[(i + 1) % m] as usize]).sqrt())
            .sum();
        Some(Loop { length, vertices })
    }
}

/// The generator loops of the geodesic balls of `radius` around `seeds`, shortest first, each once.
pub(super) fn find_loops(mesh: &TriMesh, adj: &Adjacency, seeds: &[u32], radius: f64) -> Vec<Loop> {
    let n = mesh.vertices.len();
    // One ball's buffers per chunk of seeds (they are as long as the mesh).
    let chunk = seeds
        .len()
        .div_ceil(8 * rayon::current_num_threads())
        .max(64);
    let mut all: Vec<Loop> = seeds
        .par_chunks(chunk)
        .flat_map_iter(|part| {
            let mut ball = Ball::new(n, adj.tris.len());
            part.iter()
                .flat_map(|&v| {
                    ball.grow(mesh, adj, v, radius);
                    ball.loops(mesh, adj, radius)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    all.sort_by(|a, b| {
        a.length
            .total_cmp(&b.length)
            .then_with(|| a.key().cmp(&b.key()))
    });
    let mut seen = HashSet::new();
    all.retain(|c| seen.insert(c.key()));
    all
}

/// A geodesic `spacing`-net of the referenced vertices among `vertices` (ascending): every one is
/// within `spacing` (along the edges) of a seed. Greedy in index order (deterministic).
pub(super) fn net(
    mesh: &TriMesh,
    adj: &Adjacency,
    spacing: f64,
    vertices: impl Iterator<Item = u32>,
) -> Vec<u32> {
    let n = mesh.vertices.len();
    let mut covered = vec![false; n];
    let mut ball = Ball::new(n, adj.tris.len());
    let mut seeds = Vec::new();
    for v in vertices {
        if covered[v as usize] || adj.neighbours(v).is_empty() {
            continue;
        }
        seeds.push(v);
        ball.dijkstra(mesh, adj, v, spacing);
        for &u in &ball.inside {
            covered[u as usize] = true;
        }
    }
    seeds
}

/// The referenced vertices within geodesic distance `radius` of any of `sources`, ascending.
pub(super) fn around(mesh: &TriMesh, adj: &Adjacency, sources: &[u32], radius: f64) -> Vec<u32> {
    let mut ball = Ball::new(mesh.vertices.len(), adj.tris.len());
    let sources: Vec<u32> = (sources.iter().copied())
        .filter(|&v| !adj.neighbours(v).is_empty())
        .collect();
    ball.dijkstra_from(mesh, adj, &sources, radius);
    let mut inside = std::mem::take(&mut ball.inside);
    inside.sort_unstable();
    inside
}
