//! Marching squares: the zero set of a 2D field on a regular grid as polylines (closed loops
//! inside the grid, open chains where the curve leaves it).
//!
//! Nodes are sampled in parallel (rayon over rows); a node with `f < 0` is inside. Each cell
//! with a sign change gets one segment, or two for the saddle cases 5 and 10, which are resolved
//! by the sign of `f` at the cell centre (evaluated, so neighbouring cells never disagree: the
//! crossing points live on edges shared by both cells, and the decision is per cell). Segments
//! are chained through their shared edge crossings, so every chain that does not reach the grid
//! border is closed. Crossing points start from linear interpolation and are refined along the
//! edge by the Illinois variant of regula falsi. `O(nx·ny)` field evaluations plus
//! `O(crossings × refine)`. Reference: Lorensen & Cline 1987 (the 2D analogue of marching cubes).

use rayon::prelude::*;

/// A batch evaluator: `batch(xs, out)` sets `out[i] = f(xs[i])` (input units).
pub type BatchEval<'a> = dyn Fn(&[[f64; 2]], &mut [f64]) + Sync + 'a;

/// The sampling rectangle and its resolution.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Grid2 {
    /// Lower-left corner (input units).
    pub min: [f64; 2],
    /// Upper-right corner (input units).
    pub max: [f64; 2],
    /// Cells along x (≥ 1).
    pub nx: usize,
    /// Cells along y (≥ 1).
    pub ny: usize,
}

impl Grid2 {
    /// Node `(i, j)` position.
    #[inline]
    pub fn node(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.min[0] + (self.max[0] - self.min[0]) * i as f64 / self.nx as f64,
            self.min[1] + (self.max[1] - self.min[1]) * j as f64 / self.ny as f64,
        ]
    }

    /// Cell diagonal length.
    pub fn cell_diagonal(&self) -> f64 {
        let hx = (self.max[0] - self.min[0]) / self.nx as f64;
        let hy = (self.max[1] - self.min[1]) / self.ny as f64;
        hx.hypot(hy)
    }
}

/// A contour piece.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Polyline {
    /// Vertices in order (input units). A closed loop does not repeat its first vertex.
    pub points: Vec<[f64; 2]>,
    /// True when the piece is a closed loop.
    pub closed: bool,
}

/// Contouring options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarchingParams {
    /// Regula-falsi refinement steps per crossing (default 6; 0 = linear interpolation only).
    pub refine_steps: usize,
}

impl Default for MarchingParams {
    fn default() -> Self {
        MarchingParams { refine_steps: 6 }
    }
}

/// Node values, row-major `(ny + 1) × (nx + 1)`, sampled in parallel.
pub fn sample_grid(field: &(dyn Fn(&[f64; 2]) -> f64 + Sync), grid: &Grid2) -> Vec<f64> {
    let w = grid.nx + 1;
    let mut v = vec![0.0; w * (grid.ny + 1)];
    v.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, x) in row.iter_mut().enumerate() {
            *x = field(&grid.node(i, j));
        }
    });
    v
}

/// Node values like [`sample_grid`], but blocks of `block × block` cells on which `sign_test`
/// proves one sign (`Some(f(centre))` for the ball around the block centre) are not sampled:
/// their nodes get the centre value (right sign, never interpolated, because no cell of such a
/// block has a sign change). Nodes shared with an unproven block are always evaluated.
pub fn sample_grid_blocked(
    field: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    sign_test: &(dyn Fn(&[f64; 2], f64) -> Option<f64> + Sync),
    grid: &Grid2,
    block: usize,
) -> Vec<f64> {
    let b = block.max(1);
    let (bx, by) = (grid.nx.div_ceil(b), grid.ny.div_ceil(b));
    let proven: Vec<Option<f64>> = (0..bx * by)
        .into_par_iter()
        .map(|k| {
            let (i0, j0) = ((k % bx) * b, (k / bx) * b);
            let (i1, j1) = ((i0 + b).min(grid.nx), (j0 + b).min(grid.ny));
            let (lo, hi) = (grid.node(i0, j0), grid.node(i1, j1));
            let c = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
            sign_test(&c, 0.5 * (hi[0] - lo[0]).hypot(hi[1] - lo[1]))
        })
        .collect();
    let w = grid.nx + 1;
    let mut v = vec![0.0; w * (grid.ny + 1)];
    v.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, x) in row.iter_mut().enumerate() {
            let blocks_i = [i.saturating_sub(1) / b, (i / b).min(bx - 1)];
            let blocks_j = [j.saturating_sub(1) / b, (j / b).min(by - 1)];
            let mut placeholder = None;
            let mut all_proven = true;
            for bj in blocks_j {
                for bi in blocks_i {
                    // Only blocks that actually contain node (i, j).
                    let contains = (bi * b..=(bi * b + b)).contains(&i)
                        && (bj * b..=(bj * b + b)).contains(&j);
                    if contains {
                        match proven[bj * bx + bi] {
                            Some(f) => placeholder = Some(f),
                            None => all_proven = false,
                        }
                    }
                }
            }
            *x = match (all_proven, placeholder) {
                (true, Some(f)) => f,
                _ => field(&grid.node(i, j)),
            };
        }
    });
    v
}

/// Contour the zero set of `field` over `grid`.
///
/// ```
/// use rbfsurf::polygonize::marching_squares::{contour, Grid2, MarchingParams};
/// let g = Grid2 { min: [-2.0, -2.0], max: [2.0, 2.0], nx: 40, ny: 40 };
/// let c = contour(&|p: &[f64; 2]| p[0].hypot(p[1]) - 1.0, &g, &MarchingParams::default());
/// assert_eq!(c.len(), 1);
/// assert!(c[0].closed);
/// ```
pub fn contour(
    field: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    grid: &Grid2,
    params: &MarchingParams,
) -> Vec<Polyline> {
    let values = sample_grid(field, grid);
    contour_values(field, &values, grid, params)
}

/// Contour from already sampled node values (`field` is used for saddles and refinement).
pub fn contour_values(
    field: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    values: &[f64],
    grid: &Grid2,
    params: &MarchingParams,
) -> Vec<Polyline> {
    let batch = |xs: &[[f64; 2]], out: &mut [f64]| {
        for (o, x) in out.iter_mut().zip(xs) {
            *o = field(x);
        }
    };
    contour_values_batch(field, &batch, values, grid, params)
}

/// [`contour_values`] with a batch evaluator for the crossing refinement: all crossings take
/// their regula-falsi steps in lockstep, each step one parallel batch call (`batch(xs, out)`
/// must give the same values as `field`). Same output as [`contour_values`].
pub fn contour_values_batch(
    field: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    batch: &BatchEval,
    values: &[f64],
    grid: &Grid2,
    params: &MarchingParams,
) -> Vec<Polyline> {
    let segs = segments(field, values, grid);
    let mut edges: Vec<usize> = segs.iter().flat_map(|&(a, b)| [a, b]).collect();
    edges.sort_unstable();
    edges.dedup();
    let points = edge_points(batch, values, grid, &edges, params.refine_steps);
    let at = |e: &usize| points[edges.binary_search(e).unwrap_or(0)];
    chain(&segs)
        .into_iter()
        .map(|(es, closed)| Polyline {
            points: es.iter().map(at).collect(),
            closed,
        })
        .collect()
}

/// Global edge id: horizontal `(i,j)–(i+1,j)` first, then vertical `(i,j)–(i,j+1)`.
fn h_edge(grid: &Grid2, i: usize, j: usize) -> usize {
    j * grid.nx + i
}

fn v_edge(grid: &Grid2, i: usize, j: usize) -> usize {
    (grid.ny + 1) * grid.nx + j * (grid.nx + 1) + i
}

/// The two end nodes `(i, j)` of an edge.
fn edge_nodes(grid: &Grid2, e: usize) -> ((usize, usize), (usize, usize)) {
    let h = (grid.ny + 1) * grid.nx;
    if e < h {
        let (j, i) = (e / grid.nx, e % grid.nx);
        ((i, j), (i + 1, j))
    } else {
        let e = e - h;
        let (j, i) = (e / (grid.nx + 1), e % (grid.nx + 1));
        ((i, j), (i, j + 1))
    }
}

/// Segments as pairs of edge ids, cell by cell (parallel over rows).
fn segments(
    field: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    values: &[f64],
    grid: &Grid2,
) -> Vec<(usize, usize)> {
    let w = grid.nx + 1;
    let inside = |i: usize, j: usize| values[j * w + i] < 0.0;
    (0..grid.ny)
        .into_par_iter()
        .flat_map_iter(|j| {
            let mut out = Vec::new();
            for i in 0..grid.nx {
                let c = [
                    inside(i, j),
                    inside(i + 1, j),
                    inside(i + 1, j + 1),
                    inside(i, j + 1),
                ];
                // edges: bottom, right, top, left; edge k joins corners k and (k+1) % 4
                let e = [
                    h_edge(grid, i, j),
                    v_edge(grid, i + 1, j),
                    h_edge(grid, i, j + 1),
                    v_edge(grid, i, j),
                ];
                let cut: Vec<usize> = (0..4).filter(|&k| c[k] != c[(k + 1) % 4]).collect();
                match cut.len() {
                    2 => out.push((e[cut[0]], e[cut[1]])),
                    4 => {
                        let mid = [
                            0.5 * (grid.node(i, j)[0] + grid.node(i + 1, j)[0]),
                            0.5 * (grid.node(i, j)[1] + grid.node(i, j + 1)[1]),
                        ];
                        let centre_inside = field(&mid) < 0.0;
                        // Isolate the corners whose sign differs from the centre's.
                        if c[0] != centre_inside {
                            out.push((e[3], e[0]));
                            out.push((e[1], e[2]));
                        } else {
                            out.push((e[0], e[1]));
                            out.push((e[2], e[3]));
                        }
                    }
                    _ => {}
                }
            }
            out
        })
        .collect()
}

/// Regula-falsi state of one edge crossing (Illinois variant).
#[derive(Clone, Copy)]
struct Falsi {
    pa: [f64; 2],
    pb: [f64; 2],
    ta: f64,
    tb: f64,
    fa: f64,
    fb: f64,
    side: i8,
    t: f64,
    done: bool,
}

impl Falsi {
    fn at(&self, t: f64) -> [f64; 2] {
        let (pa, pb) = (self.pa, self.pb);
        [pa[0] + t * (pb[0] - pa[0]), pa[1] + t * (pb[1] - pa[1])]
    }

    fn step(&mut self, ft: f64) {
        if ft == 0.0 || !ft.is_finite() {
            self.done = true;
            return;
        }
        if (ft < 0.0) == (self.fa < 0.0) {
            (self.ta, self.fa) = (self.t, ft);
            if self.side == -1 {
                self.fb *= 0.5;
            }
            self.side = -1;
        } else {
            (self.tb, self.fb) = (self.t, ft);
            if self.side == 1 {
                self.fa *= 0.5;
            }
            self.side = 1;
        }
        self.t = if self.fa == self.fb {
            0.5 * (self.ta + self.tb)
        } else {
            self.ta + (self.tb - self.ta) * self.fa / (self.fa - self.fb)
        };
    }
}

/// The zero crossings on `edges`, refined along each edge in lockstep.
fn edge_points(
    batch: &BatchEval,
    values: &[f64],
    grid: &Grid2,
    edges: &[usize],
    steps: usize,
) -> Vec<[f64; 2]> {
    let w = grid.nx + 1;
    let mut st: Vec<Falsi> = edges
        .iter()
        .map(|&e| {
            let ((ia, ja), (ib, jb)) = edge_nodes(grid, e);
            let (fa, fb) = (values[ja * w + ia], values[jb * w + ib]);
            Falsi {
                pa: grid.node(ia, ja),
                pb: grid.node(ib, jb),
                ta: 0.0,
                tb: 1.0,
                fa,
                fb,
                side: 0,
                t: if fa == fb { 0.5 } else { fa / (fa - fb) },
                done: false,
            }
        })
        .collect();
    for _ in 0..steps {
        let active: Vec<usize> = (0..st.len()).filter(|&k| !st[k].done).collect();
        if active.is_empty() {
            break;
        }
        let xs: Vec<[f64; 2]> = active.iter().map(|&k| st[k].at(st[k].t)).collect();
        let mut fs = vec![0.0; xs.len()];
        xs.par_chunks(64)
            .zip(fs.par_chunks_mut(64))
            .for_each(|(x, f)| batch(x, f));
        for (&k, &f) in active.iter().zip(&fs) {
            st[k].step(f);
        }
    }
    st.iter().map(|s| s.at(s.t.clamp(0.0, 1.0))).collect()
}

/// Chain segments into polylines of edge ids; returns `(edges, closed)`.
fn chain(segs: &[(usize, usize)]) -> Vec<(Vec<usize>, bool)> {
    use std::collections::HashMap;
    let mut adj: HashMap<usize, Vec<usize>> = HashMap::new();
    for (s, &(a, b)) in segs.iter().enumerate() {
        adj.entry(a).or_default().push(s);
        adj.entry(b).or_default().push(s);
    }
    let mut used = vec![false; segs.len()];
    let mut out = Vec::new();
    // Open chains start at an edge with one incident segment (the grid border).
    let mut starts: Vec<usize> = adj
        .iter()
        .filter(|(_, v)| v.len() == 1)
        .map(|(&e, _)| e)
        .collect();
    starts.sort_unstable();
    let all: Vec<usize> = {
        let mut v: Vec<usize> = adj.keys().copied().collect();
        v.sort_unstable();
        v
    };
    for start in starts.into_iter().chain(all) {
        let Some(&s0) = adj[&start].iter().find(|&&s| !used[s]) else {
            continue;
        };
        let mut edges = vec![start];
        let (mut cur, mut seg) = (start, s0);
        loop {
            used[seg] = true;
            let (a, b) = segs[seg];
            let next = if a == cur { b } else { a };
            if next == start {
                out.push((edges, true));
                break;
            }
            edges.push(next);
            cur = next;
            match adj[&cur].iter().find(|&&s| !used[s]) {
                Some(&s) => seg = s,
                None => {
                    out.push((edges, false));
                    break;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_gives_one_closed_accurate_loop() {
        let g = Grid2 {
            min: [-1.5, -1.3],
            max: [1.7, 1.5],
            nx: 37,
            ny: 29,
        };
        let f = |p: &[f64; 2]| p[0].hypot(p[1]) - 1.0;
        let c = contour(&f, &g, &MarchingParams::default());
        assert_eq!(c.len(), 1);
        assert!(c[0].closed);
        assert!(c[0].points.len() > 50);
        for p in &c[0].points {
            assert!((p[0].hypot(p[1]) - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn two_circles_and_a_clipped_one() {
        let g = Grid2 {
            min: [-3.0, -1.0],
            max: [3.0, 1.0],
            nx: 90,
            ny: 30,
        };
        let f = |p: &[f64; 2]| {
            let a = (p[0] + 1.5).hypot(p[1]) - 0.5;
            let b = (p[0] - 1.5).hypot(p[1]) - 0.5;
            let c = (p[0] - 3.0).hypot(p[1] - 1.0) - 0.3;
            a.min(b).min(c)
        };
        let c = contour(&f, &g, &MarchingParams::default());
        assert_eq!(c.iter().filter(|p| p.closed).count(), 2);
        assert_eq!(c.iter().filter(|p| !p.closed).count(), 1);
    }

    #[test]
    fn blocked_sampling_gives_the_same_contour() {
        let g = Grid2 {
            min: [-1.5, -1.3],
            max: [1.7, 1.5],
            nx: 64,
            ny: 56,
        };
        let f = |p: &[f64; 2]| p[0].hypot(p[1]) - 1.0;
        // |∇f| = 1, so the sign is proven when |f(c)| > ρ.
        let test = |c: &[f64; 2], rho: f64| {
            let v = f(c);
            (v.abs() > rho).then_some(v)
        };
        let full = sample_grid(&f, &g);
        let blocked = sample_grid_blocked(&f, &test, &g, 8);
        let same_sign = full
            .iter()
            .zip(&blocked)
            .all(|(a, b)| (*a < 0.0) == (*b < 0.0));
        assert!(same_sign);
        assert!(full.iter().zip(&blocked).filter(|(a, b)| a != b).count() > 100);
        let p = MarchingParams::default();
        assert_eq!(
            contour_values(&f, &full, &g, &p),
            contour_values(&f, &blocked, &g, &p)
        );
    }

    #[test]
    fn saddles_are_consistent() {
        // f = x·y has saddles at every cell around the origin; the curve is the two axes.
        let g = Grid2 {
            min: [-1.05, -0.95],
            max: [0.95, 1.05],
            nx: 20,
            ny: 20,
        };
        let f = |p: &[f64; 2]| p[0] * p[1] + 1e-3;
        let c = contour(&f, &g, &MarchingParams::default());
        // Two open hyperbola branches, each ending on the border.
        assert_eq!(c.len(), 2);
        assert!(c.iter().all(|p| !p.closed));
        let total: usize = c.iter().map(|p| p.points.len()).sum();
        assert!(total >= 40);
    }
}
