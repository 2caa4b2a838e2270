//! Small handles removed from a closed mesh: topological noise (Guskov & Wood, *Topological noise
//! removal*, Graphics Interface 2001; Wood et al., *Removing excess topology from isosurfaces*,
//! ACM TOG 2004).
//!
//! Where two parts of a surface come closer than the data can separate (a limb beside the body, an
//! ear beside the head), the zero set can join them with a thin bridge or open a pinhole through a
//! thin wall: a handle whose shortest non-separating loop is much shorter than any real feature.
//! Every vertex seeds a geodesic ball (Dijkstra over the edges) of radius `max_loop / 2`. A ball is a
//! disc (`χ = 1`) on the surface away from handles; one that is not carries cycles, whose generators
//! come from a tree–cotree split of the ball (the Dijkstra tree; a spanning forest of its triangles
//! plus one node for everything outside). A generator is a handle loop when cutting the surface along
//! it leaves it connected (a simple closed curve separates a closed orientable surface exactly when
//! it bounds). The shortest such loops are cut first: the triangles at the loop's vertices are
//! removed and each of the two borders left is closed by a fan around its centroid, which lowers
//! the genus by one. A cut that would not leave exactly two simple borders, or whose result is not
//! closed, manifold and oriented with the genus one lower, is undone. Real handles longer than
//! `max_loop` around (a torus's tube, a cup's handle) are never touched.
//!
//! Cost: one ball per vertex, `O(V · b log b)` for balls of `b` vertices (in parallel), plus a cut
//! test `O(F)` per candidate loop, tried shortest first.

use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, HashSet};

use crate::geometry::{Point3, TriMesh, add, cross, dist2, norm, normalized, scale, sub};

/// What [`remove_small_handles`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HandleStats {
    /// Handles cut.
    pub removed: usize,
    /// Length of each cut loop, mesh units, in the order they were cut.
    pub loop_lengths: Vec<f64>,
    /// Non-separating loops found but not cut (the cut did not leave a closed manifold one genus
    /// lower), or left because [`MAX_CUTS`] was reached.
    pub kept: usize,
}

/// Most handles cut in one call.
pub const MAX_CUTS: usize = 256;

/// Rounds of detection (a cut can expose a new short loop nearby).
const ROUNDS: usize = 4;

/// Cut every handle of the closed, manifold, oriented `mesh` whose shortest non-separating loop is
/// at most `max_loop` long (mesh units); a mesh with a border or a non-manifold edge is left
/// alone. Deterministic: the candidates are ordered by length, then by their vertices.
pub fn remove_small_handles(mesh: &mut TriMesh, max_loop: f64) -> HandleStats {
    let mut stats = HandleStats::default();
    if max_loop.is_nan() || max_loop <= 0.0 || mesh.triangles.is_empty() {
        return stats;
    }
    let Some(mut genus) = closed_genus(mesh) else {
        return stats;
    };
    let start = genus;
    let original = mesh.clone();
    let mut failed: HashSet<Vec<u32>> = HashSet::new();
    for _ in 0..ROUNDS {
        if genus == 0 || stats.removed >= MAX_CUTS {
            break;
        }
        let Some(adj) = Adjacency::new(mesh) else {
            break;
        };
        let spacing = max_loop / 2.0;
        let seeds = net(mesh, &adj, spacing);
        let mut candidates = find_loops(mesh, &adj, &seeds, max_loop / 2.0 + spacing);
        candidates.retain(|c| !failed.contains(&c.key()));
        if candidates.is_empty() {
            break;
        }
        let before = (mesh.clone(), genus, stats.clone(), failed.clone());
        let mut cut = cut_loops(
            mesh,
            adj,
            &candidates,
            max_loop,
            Cuts::Batch,
            &mut genus,
            &mut failed,
            &mut stats,
        );
        if cut > 0 && closed_genus(mesh) != Some(genus) {
            // A loop made separating by an earlier cut of the round was cut too: redo the round
            // one cut at a time.
            (*mesh, genus, stats, failed) = before;
            let Some(adj) = Adjacency::new(mesh) else {
                break;
            };
            cut = cut_loops(
                mesh,
                adj,
                &candidates,
                max_loop,
                Cuts::OneByOne,
                &mut genus,
                &mut failed,
                &mut stats,
            );
        }
        if cut == 0 {
            break;
        }
    }
    // Each cut was checked locally (two simple borders, Euler characteristic up by 2); the whole
    // mesh is checked once more.
    if stats.removed > 0 && closed_genus(mesh) != Some(start - stats.removed as i64) {
        *mesh = original;
        stats.kept += stats.removed;
        stats.removed = 0;
        stats.loop_lengths.clear();
    }
    stats
}

/// How a round applies its cuts.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Cuts {
    /// All cuts of the round against the round's adjacency (loops sharing no vertex with an
    /// earlier cut's triangles); checked once at the end of the round.
    Batch,
    /// The adjacency rebuilt after each cut (the fallback when a batch round fails its check).
    OneByOne,
}

/// Cuts the non-separating loops among `candidates` (shortest first) while the genus is
/// positive; returns how many. `mesh.triangles` must be `adj.tris` on entry.
#[allow(clippy::too_many_arguments)]
fn cut_loops(
    mesh: &mut TriMesh,
    mut adj: Adjacency,
    candidates: &[Loop],
    max_loop: f64,
    mode: Cuts,
    genus: &mut i64,
    failed: &mut HashSet<Vec<u32>>,
    stats: &mut HandleStats,
) -> usize {
    let mut touched = vec![false; mesh.vertices.len()];
    let mut dead = vec![false; adj.tris.len()];
    let mut cut = 0;
    for c in candidates {
        if *genus == 0 {
            break;
        }
        if c.vertices.iter().any(|&v| touched[v as usize]) || !adj.non_separating(&c.vertices) {
            continue;
        }
        let Some(c) = shortest_handle_loop(mesh, &adj, c.clone(), max_loop) else {
            continue;
        };
        if c.vertices.iter().any(|&v| touched[v as usize]) {
            continue;
        }
        if stats.removed >= MAX_CUTS {
            stats.kept += 1;
            continue;
        }
        let Some(band) = cut_and_cap(mesh, &adj, &c.vertices, &mut dead) else {
            failed.insert(c.key());
            stats.kept += 1;
            continue;
        };
        *genus -= 1;
        for v in band {
            touched[v as usize] = true;
        }
        touched.resize(mesh.vertices.len(), true);
        stats.removed += 1;
        stats.loop_lengths.push(c.length);
        cut += 1;
        if mode == Cuts::OneByOne {
            compact(mesh, &mut dead);
            match Adjacency::new(mesh) {
                Some(a) => adj = a,
                None => break,
            }
            dead = vec![false; adj.tris.len()];
        }
    }
    compact(mesh, &mut dead);
    cut
}

/// Drops the triangles flagged in `dead` (the first `dead.len()` of the mesh; the caps after
/// them stay) and clears the flags.
fn compact(mesh: &mut TriMesh, dead: &mut Vec<bool>) {
    let mut i = 0;
    mesh.triangles.retain(|_| {
        i += 1;
        !dead.get(i - 1).copied().unwrap_or(false)
    });
    dead.clear();
}

/// Steps of [`shortest_near`] from a net seed's loop towards the handle's shortest loop.
const DESCENT_STEPS: usize = 3;

/// The handle's shortest loop of at most `max_loop`, searched near `found` and then near each
/// shorter loop found, while that shortens it.
fn shortest_handle_loop(
    mesh: &TriMesh,
    adj: &Adjacency,
    found: Loop,
    max_loop: f64,
) -> Option<Loop> {
    let mut best = found;
    for _ in 0..DESCENT_STEPS {
        match shortest_near(mesh, adj, &best, max_loop) {
            Some(c) if c.length < best.length => best = c,
            _ => break,
        }
    }
    (best.length <= max_loop).then_some(best)
}

/// The shortest non-separating loop of at most `max_loop` through the vertices within
/// `max_loop / 4` of the non-separating loop `found` (a loop from a net seed passes within that
/// distance of a handle's shortest loop but may be longer), from the balls of radius
/// `max_loop / 2` around each: the shortest non-separating loop through a vertex is a generator of
/// its shortest-path tree.
fn shortest_near(mesh: &TriMesh, adj: &Adjacency, found: &Loop, max_loop: f64) -> Option<Loop> {
    let mut ball = Ball::new(mesh.vertices.len(), adj.tris.len());
    let mut near: Vec<u32> = Vec::new();
    for &v in &found.vertices {
        ball.dijkstra(mesh, adj, v, max_loop / 8.0);
        near.extend(&ball.inside);
    }
    near.sort_unstable();
    near.dedup();
    let loops = find_loops(mesh, adj, &near, max_loop / 2.0);
    loops.into_iter().find(|c| adj.non_separating(&c.vertices))
}

/// Total genus when the mesh is closed, manifold and oriented.
fn closed_genus(mesh: &TriMesh) -> Option<i64> {
    let t = super::topology::analyze(mesh);
    (t.watertight && t.manifold && t.oriented)
        .then_some(t.genus)
        .flatten()
}

/// A closed edge path on the mesh.
#[derive(Debug, Clone)]
struct Loop {
    /// Length, mesh units.
    length: f64,
    /// Vertices in order (the last joins the first).
    vertices: Vec<u32>,
}

impl Loop {
    /// The vertex set, sorted: the same loop found from different seeds has the same key.
    fn key(&self) -> Vec<u32> {
        let mut k = self.vertices.clone();
        k.sort_unstable();
        k
    }
}

/// Vertex and triangle neighbourhoods of a closed, manifold, oriented mesh.
struct Adjacency {
    /// The mesh's triangles (corners of each).
    tris: Vec<[u32; 3]>,
    /// Neighbours of each vertex, CSR (`vstart`, `vlist`).
    vstart: Vec<u32>,
    vlist: Vec<u32>,
    /// Triangles at each vertex, CSR (`tstart`, `tlist`).
    tstart: Vec<u32>,
    tlist: Vec<u32>,
    /// The triangle across edge `k` (corner `k` to corner `k + 1`) of each triangle.
    across: Vec<[u32; 3]>,
}

impl Adjacency {
    /// `None` unless every edge has exactly two triangles that traverse it in opposite directions.
    fn new(mesh: &TriMesh) -> Option<Adjacency> {
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

    fn neighbours(&self, v: u32) -> &[u32] {
        &self.vlist[self.vstart[v as usize] as usize..self.vstart[v as usize + 1] as usize]
    }

    fn triangles_at(&self, v: u32) -> &[u32] {
        &self.tlist[self.tstart[v as usize] as usize..self.tstart[v as usize + 1] as usize]
    }

    /// Edge `k` of triangle `t` as a sorted pair.
    fn edge(&self, t: u32, k: usize) -> (u32, u32) {
        let tri = self.tris[t as usize];
        let (a, b) = (tri[k], tri[(k + 1) % 3]);
        (a.min(b), a.max(b))
    }

    /// The two triangles on edge `a`–`b`.
    fn sides(&self, a: u32, b: u32) -> Option<(u32, u32)> {
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
    fn non_separating(&self, cycle: &[u32]) -> bool {
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

/// Per-thread buffers of the geodesic balls.
struct Ball {
    dist: Vec<f64>,
    parent: Vec<u32>,
    /// Local index of each triangle inside the ball, or `u32::MAX`.
    local: Vec<u32>,
    /// Vertices reached (to reset `dist`).
    reached: Vec<u32>,
    /// Vertices of the ball.
    inside: Vec<u32>,
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
    fn new(vertices: usize, triangles: usize) -> Ball {
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
    fn grow(&mut self, mesh: &TriMesh, adj: &Adjacency, seed: u32, radius: f64) {
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
    fn dijkstra(&mut self, mesh: &TriMesh, adj: &Adjacency, seed: u32, radius: f64) {
        self.reset();
        let p = &mesh.vertices;
        let mut heap = BinaryHeap::new();
        self.dist[seed as usize] = 0.0;
        self.reached.push(seed);
        heap.push(Entry(0.0, seed));
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
    fn loops(&self, mesh: &TriMesh, adj: &Adjacency, radius: f64) -> Vec<Loop> {
        let chi = self.inside.len() as i64 - self.edges_inside(adj, radius) as i64
            + self.tris.len() as i64;
        if chi >= 1 {
            return Vec::new(); // a disc (or a whole sphere)
        }
        let outside = self.tris.len();
        let mut sets = Dsu::new(outside + 1);
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
                u32::MAX => outside,
                l => l as usize,
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

/// Disjoint sets with path halving.
struct Dsu(Vec<usize>);
impl Dsu {
    fn new(n: usize) -> Dsu {
        Dsu((0..n).collect())
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    /// Joins the sets of `a` and `b`; false when they were one already.
    fn union(&mut self, a: usize, b: usize) -> bool {
        let (a, b) = (self.find(a), self.find(b));
        if a == b {
            return false;
        }
        self.0[a.max(b)] = a.min(b);
        true
    }
}

/// The generator loops of the geodesic balls of `radius` around `seeds`, shortest first, each once.
fn find_loops(mesh: &TriMesh, adj: &Adjacency, seeds: &[u32], radius: f64) -> Vec<Loop> {
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

/// A geodesic `spacing`-net of the referenced vertices: every vertex is within `spacing` (along
/// the edges) of a seed. Greedy in index order (deterministic).
fn net(mesh: &TriMesh, adj: &Adjacency, spacing: f64) -> Vec<u32> {
    let n = mesh.vertices.len();
    let mut covered = vec![false; n];
    let mut ball = Ball::new(n, adj.tris.len());
    let mut seeds = Vec::new();
    for v in 0..n as u32 {
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

/// Removes the triangles at the loop's vertices (flags them in `dead`) and closes each of the two
/// borders left with a fan around its centroid (appended). Returns the vertices of the removed
/// triangles, or `None` (mesh unchanged) unless exactly two simple borders are left and the band
/// is an annulus.
fn cut_and_cap(
    mesh: &mut TriMesh,
    adj: &Adjacency,
    cycle: &[u32],
    dead: &mut [bool],
) -> Option<Vec<u32>> {
    let mut band: Vec<u32> = cycle
        .iter()
        .flat_map(|&v| adj.triangles_at(v).iter().copied())
        .collect();
    band.sort_unstable();
    band.dedup();
    let in_band: HashSet<u32> = band.iter().copied().collect();
    // The removed triangles' half-edges facing kept ones, in the removed triangles' direction:
    // the borders as the caps must traverse them.
    let mut next: HashMap<u32, u32> = HashMap::new();
    for &t in &band {
        for k in 0..3 {
            if !in_band.contains(&adj.across[t as usize][k]) {
                let tri = adj.tris[t as usize];
                if next.insert(tri[k], tri[(k + 1) % 3]).is_some() {
                    return None; // a border that touches itself
                }
            }
        }
    }
    let mut borders: Vec<Vec<u32>> = Vec::new();
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut used = HashSet::new();
    for s in starts {
        if used.contains(&s) {
            continue;
        }
        let mut border = vec![s];
        used.insert(s);
        let mut v = *next.get(&s)?;
        while v != s {
            if !used.insert(v) {
                return None;
            }
            border.push(v);
            v = *next.get(&v)?;
        }
        borders.push(border);
    }
    if borders.len() != 2 || borders.iter().any(|b| b.len() < 3) {
        return None;
    }
    // The band must be an open annulus (V − E + F = 0 over its vertices whose every triangle
    // goes, its edges between two removed triangles, its triangles): then removing it and adding
    // the two caps raises the Euler characteristic by 2, and the genus drops by one.
    let gone = |v: u32| adj.triangles_at(v).iter().all(|t| in_band.contains(t));
    let mut inner: Vec<u32> = band.iter().flat_map(|&t| adj.tris[t as usize]).collect();
    inner.sort_unstable();
    inner.dedup();
    let v_inner = inner.iter().filter(|&&v| gone(v)).count() as i64;
    let e_inner = band
        .iter()
        .map(|&t| {
            (0..3)
                .filter(|&k| {
                    let u = adj.across[t as usize][k];
                    in_band.contains(&u) && u > t
                })
                .count()
        })
        .sum::<usize>() as i64;
    if v_inner - e_inner + band.len() as i64 != 0 {
        return None;
    }
    for &t in &band {
        dead[t as usize] = true;
    }
    for border in borders {
        cap(mesh, &border);
    }
    Some(inner)
}

/// Closes `border` (in the direction the cap traverses it) with a fan around a new vertex at
/// its centroid.
fn cap(mesh: &mut TriMesh, border: &[u32]) {
    let p = &mesh.vertices;
    let centroid = scale(
        border.iter().fold([0.0; 3], |s, &v| add(s, p[v as usize])),
        1.0 / border.len() as f64,
    );
    let c = mesh.vertices.len() as u32;
    let mut normal = [0.0; 3];
    for i in 0..border.len() {
        let (a, b) = (border[i], border[(i + 1) % border.len()]);
        normal = add(
            normal,
            cross(
                sub(mesh.vertices[a as usize], centroid),
                sub(mesh.vertices[b as usize], centroid),
            ),
        );
        mesh.triangles.push([a, b, c]);
    }
    let had_normals = mesh.normals.len() == mesh.vertices.len();
    let had_colors = mesh.colors.len() == mesh.vertices.len();
    if had_colors {
        let mut rgb = [0.0f32; 3];
        for &v in border {
            for (s, x) in rgb.iter_mut().zip(mesh.colors[v as usize]) {
                *s += x / border.len() as f32;
            }
        }
        mesh.colors.push(rgb);
    }
    mesh.vertices.push(centroid);
    if had_normals {
        let n: Point3 = normalized(normal).unwrap_or([0.0, 0.0, 1.0]);
        debug_assert!(norm(n) > 0.0);
        mesh.normals.push(n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::{cube, merge, torus};
    use crate::mesh::topology::analyze;

    fn shifted(mut m: TriMesh, d: Point3) -> TriMesh {
        m.vertices.iter_mut().for_each(|p| *p = add(*p, d));
        m
    }

    #[test]
    fn a_thin_handle_is_cut_along_its_shortest_loop() {
        // Tube radius 0.05: the meridian is 2π · 0.05 ≈ 0.31 (0.306 as a 12-gon).
        let mut m = torus(1.0, 0.05, 96, 12);
        assert_eq!(analyze(&m).genus, Some(1));
        let s = remove_small_handles(&mut m, 0.5);
        assert_eq!(s.removed, 1, "{s:?}");
        let t = analyze(&m);
        assert!(t.watertight && t.manifold && t.oriented, "{t:?}");
        assert_eq!((t.genus, t.components), (Some(0), 1), "{t:?}");
        let l = s.loop_lengths[0];
        assert!((0.30..0.32).contains(&l), "loop {l}");
        // The caps close the tube where the band was cut: the mesh stays within the torus.
        for p in &m.vertices {
            let rho = (p[0] * p[0] + p[1] * p[1]).sqrt();
            assert!(((rho - 1.0).powi(2) + p[2] * p[2]).sqrt() <= 0.05 + 1e-9);
        }
    }

    #[test]
    fn handles_with_longer_loops_and_spheres_are_left_alone() {
        for (mut m, max_loop) in [
            (torus(1.0, 0.05, 96, 12), 0.25), // the meridian 0.306 is longer
            (torus(1.0, 0.4, 64, 24), 1.0),   // meridian 2.5, longitude 3.8
            (cube([0.0; 3], 1.0), 10.0),      // genus 0: nothing to cut
        ] {
            let before = m.clone();
            let s = remove_small_handles(&mut m, max_loop);
            assert_eq!((s.removed, s.kept), (0, 0), "{s:?}");
            assert_eq!(m.triangles, before.triangles);
            assert_eq!(m.vertices, before.vertices);
        }
    }

    #[test]
    fn only_the_small_handle_of_two_is_cut_and_a_mesh_with_a_border_is_left_alone() {
        let thin = torus(1.0, 0.05, 96, 12);
        let fat = shifted(torus(1.0, 0.4, 64, 24), [5.0, 0.0, 0.0]);
        let mut m = merge(&thin, &fat);
        let s = remove_small_handles(&mut m, 0.5);
        assert_eq!(s.removed, 1);
        let t = analyze(&m);
        assert_eq!(
            (t.genus, t.components, t.watertight),
            (Some(1), 2, true),
            "{t:?}"
        );
        // Every triangle of the fat torus is still there.
        let shift = thin.vertices.len() as u32;
        for f in &fat.triangles {
            let f = [f[0] + shift, f[1] + shift, f[2] + shift];
            assert!(m.triangles.contains(&f));
        }
        let mut open = torus(1.0, 0.05, 96, 12);
        open.triangles.pop();
        let before = open.triangles.clone();
        assert_eq!(remove_small_handles(&mut open, 0.5), HandleStats::default());
        assert_eq!(open.triangles, before);
    }

    #[test]
    fn the_cut_is_the_same_whatever_the_thread_count() {
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut m = merge(
                &torus(1.0, 0.05, 96, 12),
                &shifted(torus(0.5, 0.03, 64, 10), [3.0, 0.0, 0.0]),
            );
            let s = pool.install(|| remove_small_handles(&mut m, 0.5));
            (s, m.triangles, m.vertices)
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.0.removed, 2);
        assert_eq!(a, b);
    }
}
