//! Marching tetrahedra inside one block of the grid: sample the block's corners, triangulate every cell
//! with the Kuhn case table, and place each vertex on its grid edge (linear interpolation plus a few
//! safeguarded Illinois regula-falsi steps, Dowell & Jarratt 1971).
//!
//! `O(c + v · s)` field evaluations for `c` block corners, `v` vertices and `s` refinement steps.
//! Vertices are keyed by global edge id and computed from the edge's canonical end points, so the same
//! edge gives bit-identical vertices in every block that touches it.

use super::grid::Grid;
use super::kuhn::{CubeEdge, TETS, TetCase};
use super::{Region, ScalarField};
use crate::geometry::{Aabb, Point3, add, normalized, scale, sub};

/// The triangles and vertices of one block, with block-local vertex indices.
#[derive(Debug, Default)]
pub(crate) struct BlockMesh {
    /// Global edge id of every local vertex.
    pub edge_ids: Vec<u64>,
    /// Vertex positions.
    pub positions: Vec<Point3>,
    /// Unit vertex normals.
    pub normals: Vec<Point3>,
    /// Triangles over the local vertices.
    pub triangles: Vec<[u32; 3]>,
    /// Field evaluations spent.
    pub evaluations: u64,
}

/// Inside test: `f < 0`. Zero (and NaN) counts as outside, so no corner lies on the surface.
#[inline]
fn inside(f: f64) -> bool {
    f < 0.0
}

/// Working state of one block.
struct Block<'a> {
    field: &'a dyn ScalarField,
    region: &'a dyn Region,
    grid: &'a Grid,
    lo: [usize; 3],
    /// Corners per axis (`cells + 1`).
    dims: [usize; 3],
    values: Vec<f64>,
    /// Local edge slot (`local corner · 7 + dir − 1`) → local vertex index, `u32::MAX` when absent.
    slots: Vec<u32>,
    refine_steps: usize,
    out: BlockMesh,
}

/// Cells per axis of the tiles a block is sampled in.
const TILE: usize = 4;

/// Field values at the `dims` corners starting at grid corner `lo`, x fastest, plus the number of
/// field evaluations spent.
///
/// A tile outside `keep` is not sampled either: its corners get `+∞` (outside). None of its cells
/// is triangulated (the region is monotone, so no cell of the tile touches it), so these values are
/// never used for geometry.
///
/// The block is cut into tiles of `TILE³` cells. A tile the field rules out
/// (`may_contain_zero(tile) == false`, so `f` has one sign on the closed tile) is not sampled: its
/// corners get the value at the tile's centre, which has that sign. Only edges with a sign change are
/// interpolated, and no such edge lies in a ruled-out tile, so these stand-in values are never used
/// for geometry. Corners of the other tiles are evaluated with [`ScalarField::values_in`], once each.
fn sample_corners(
    field: &dyn ScalarField,
    keep: &dyn Region,
    grid: &Grid,
    lo: [usize; 3],
    dims: [usize; 3],
) -> (Vec<f64>, u64) {
    let mut values = vec![f64::NAN; dims.iter().product()];
    let idx = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
    let tiles = [0, 1, 2].map(|a| (dims[a] - 1).div_ceil(TILE).max(1));
    let mut skipped = Vec::new();
    let (mut pts, mut out, mut slots) = (Vec::new(), Vec::new(), Vec::new());
    let mut evaluations = 0u64;
    for t in 0..tiles[0] * tiles[1] * tiles[2] {
        let t3 = [
            t % tiles[0],
            (t / tiles[0]) % tiles[1],
            t / (tiles[0] * tiles[1]),
        ];
        let c0 = t3.map(|a| a * TILE);
        let c1 = [0, 1, 2].map(|a| (c0[a] + TILE).min(dims[a] - 1));
        let region = Aabb {
            min: grid.corner([lo[0] + c0[0], lo[1] + c0[1], lo[2] + c0[2]]),
            max: grid.corner([lo[0] + c1[0], lo[1] + c1[1], lo[2] + c1[2]]),
        };
        if !keep.touches(&region) {
            skipped.push((c0, c1, None));
            continue;
        }
        if !field.may_contain_zero(&region) {
            skipped.push((c0, c1, Some(region.center())));
            continue;
        }
        pts.clear();
        slots.clear();
        for k in c0[2]..=c1[2] {
            for j in c0[1]..=c1[1] {
                for i in c0[0]..=c1[0] {
                    if values[idx(i, j, k)].is_nan() {
                        pts.push(grid.corner([lo[0] + i, lo[1] + j, lo[2] + k]));
                        slots.push(idx(i, j, k));
                    }
                }
            }
        }
        out.resize(pts.len(), 0.0);
        field.values_in(&region, &pts, &mut out);
        evaluations += pts.len() as u64;
        for (&s, &v) in slots.iter().zip(&out) {
            // A NaN from the field is stored as +inf: outside, and never re-evaluated.
            values[s] = if v.is_nan() { f64::INFINITY } else { v };
        }
    }
    for (c0, c1, centre) in skipped {
        let v = centre.map_or(f64::INFINITY, |c| {
            evaluations += 1;
            let v = field.value(&c);
            if v.is_nan() || v == 0.0 {
                f64::INFINITY
            } else {
                v
            }
        });
        for k in c0[2]..=c1[2] {
            for j in c0[1]..=c1[1] {
                for i in c0[0]..=c1[0] {
                    if values[idx(i, j, k)].is_nan() {
                        values[idx(i, j, k)] = v;
                    }
                }
            }
        }
    }
    (values, evaluations)
}

/// Extracts the zero set inside block `b` of `grid`.
pub(crate) fn extract_block(
    field: &dyn ScalarField,
    region: &dyn Region,
    grid: &Grid,
    table: &[[TetCase; 16]; 6],
    b: usize,
    refine_steps: usize,
) -> BlockMesh {
    let (lo, hi) = grid.block_cells(b);
    let dims = [0, 1, 2].map(|k| hi[k] - lo[k] + 1);
    let (values, evaluations) = sample_corners(field, region, grid, lo, dims);
    let first = values.first().is_some_and(|&f| inside(f));
    if values.iter().all(|&f| inside(f) == first) {
        return BlockMesh {
            evaluations,
            ..BlockMesh::default()
        };
    }
    let mut block = Block {
        field,
        region,
        grid,
        lo,
        dims,
        slots: vec![u32::MAX; values.len() * 7],
        values,
        refine_steps,
        out: BlockMesh {
            evaluations,
            ..BlockMesh::default()
        },
    };
    for k in 0..dims[2] - 1 {
        for j in 0..dims[1] - 1 {
            for i in 0..dims[0] - 1 {
                block.cell([i, j, k], table);
            }
        }
    }
    block.out
}

impl Block<'_> {
    /// Local corner index of local corner `c`.
    #[inline]
    fn local(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Local corner `cell + bits` (bits `x + 2y + 4z`).
    #[inline]
    fn offset(cell: [usize; 3], bits: u8) -> [usize; 3] {
        [0, 1, 2].map(|k| cell[k] + ((bits >> k) & 1) as usize)
    }

    /// Triangulates the 6 tetrahedra of local cell `cell`.
    fn cell(&mut self, cell: [usize; 3], table: &[[TetCase; 16]; 6]) {
        let mut cube_mask = 0u8;
        for bits in 0..8u8 {
            if inside(self.values[self.local(Self::offset(cell, bits))]) {
                cube_mask |= 1 << bits;
            }
        }
        if cube_mask == 0 || cube_mask == 0xFF {
            return;
        }
        let global = |bits: u8| {
            let c = Self::offset(cell, bits);
            self.grid.corner([0, 1, 2].map(|k| self.lo[k] + c[k]))
        };
        let cell_box = Aabb {
            min: global(0),
            max: global(7),
        };
        if !self.region.touches(&cell_box) {
            return;
        }
        for (t, tet) in TETS.iter().enumerate() {
            let mask = (0..4).fold(0usize, |m, i| {
                m | (((cube_mask >> tet[i]) & 1) as usize) << i
            });
            let case = &table[t][mask];
            for tri in &case.tris[..case.count as usize] {
                let tri = tri.map(|e| self.vertex(cell, e));
                self.out.triangles.push(tri);
            }
        }
    }

    /// Local index of the vertex on cube edge `e` of `cell`, creating it on first use.
    fn vertex(&mut self, cell: [usize; 3], (lo_bits, dir): CubeEdge) -> u32 {
        let a = Self::offset(cell, lo_bits);
        let b = Self::offset(a, dir);
        let (ia, ib) = (self.local(a), self.local(b));
        let slot = ia * 7 + dir as usize - 1;
        if self.slots[slot] != u32::MAX {
            return self.slots[slot];
        }
        let global = |c: [usize; 3]| [0, 1, 2].map(|k| self.lo[k] + c[k]);
        let (ga, gb) = (global(a), global(b));
        let (pa, pb) = (self.grid.corner(ga), self.grid.corner(gb));
        let (fa, fb) = (self.values[ia], self.values[ib]);
        // Orient the edge from its inside end to its outside end.
        let (p_in, f_in, p_out, f_out) = if inside(fa) {
            (pa, fa, pb, fb)
        } else {
            (pb, fb, pa, fa)
        };
        let (p, evals) = locate(self.field, (p_in, f_in), (p_out, f_out), self.refine_steps);
        self.out.evaluations += evals;
        let normal = normalized(self.field.gradient(&p))
            .or_else(|| normalized(sub(p_out, p_in)))
            .unwrap_or([0.0, 0.0, 1.0]);
        let index = self.out.positions.len() as u32;
        self.out.positions.push(p);
        self.out.normals.push(normal);
        self.out
            .edge_ids
            .push(self.grid.corner_id(ga) * 7 + dir as u64 - 1);
        self.slots[slot] = index;
        index
    }
}

/// Root of the field on the segment from `p_in` (`f_in < 0`) to `p_out` (`f_out ≥ 0` or NaN): linear
/// interpolation, then `steps` safeguarded steps. The sign bracket always keeps one inside and one
/// outside end; a step takes inverse quadratic interpolation through the three best samples when it
/// lands inside the bracket no farther from the best sample than the bracket's midpoint (Brent 1973),
/// else Anderson–Björck regula falsi on the bracket, else bisection (e.g. for NaN values).
/// Returns the point and the number of field evaluations.
fn locate(
    field: &dyn ScalarField,
    (p_in, f_in): (Point3, f64),
    (p_out, f_out): (Point3, f64),
    steps: usize,
) -> (Point3, u64) {
    let at = |t: f64| add(p_in, scale(sub(p_out, p_in), t));
    if f_out == 0.0 {
        return (p_out, 0);
    }
    let mut r = Bracket {
        lo: (0.0, f_in),
        hi: (1.0, f_out),
        weights: [f_in, f_out],
        last_side: 0,
        best: vec![(0.0, f_in), (1.0, f_out)],
    };
    let mut t = r.estimate();
    let mut evals = 0;
    for _ in 0..steps {
        let f = field.value(&at(t));
        evals += 1;
        if f == 0.0 {
            return (at(t), evals);
        }
        r.update(t, f);
        t = r.estimate();
    }
    (at(t), evals)
}

/// State of the safeguarded root search on `t ∈ [0, 1]`.
struct Bracket {
    /// Inside end `(t, f)`, `f < 0`.
    lo: (f64, f64),
    /// Outside end `(t, f)`, `f ≥ 0` or NaN.
    hi: (f64, f64),
    /// Anderson–Björck-scaled values of `lo` and `hi` used by regula falsi.
    weights: [f64; 2],
    /// Which end the previous sample replaced: −1 inside, +1 outside, 0 none yet.
    last_side: i8,
    /// Up to three samples with the smallest `|f|`, best first.
    best: Vec<(f64, f64)>,
}

impl Bracket {
    /// Records the sample `(t, f)` (`f ≠ 0`) and shrinks the bracket.
    fn update(&mut self, t: f64, f: f64) {
        if inside(f) {
            if self.last_side == -1 {
                let m = 1.0 - f / self.weights[0];
                self.weights[1] *= if m > 0.0 { m } else { 0.5 };
            }
            (self.lo, self.weights[0], self.last_side) = ((t, f), f, -1);
        } else {
            if self.last_side == 1 {
                let m = 1.0 - f / self.weights[1];
                self.weights[0] *= if m > 0.0 { m } else { 0.5 };
            }
            (self.hi, self.weights[1], self.last_side) = ((t, f), f, 1);
        }
        self.best.push((t, f));
    }

    /// Next root estimate, strictly inside the bracket.
    fn estimate(&mut self) -> f64 {
        self.best.sort_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
        self.best.truncate(3);
        let (lo, hi) = (self.lo.0, self.hi.0);
        let mid = 0.5 * (lo + hi);
        let b = self.best[0].0;
        if let [(x0, y0), (x1, y1), (x2, y2)] = self.best[..] {
            let t = x0 * y1 * y2 / ((y0 - y1) * (y0 - y2))
                + x1 * y0 * y2 / ((y1 - y0) * (y1 - y2))
                + x2 * y0 * y1 / ((y2 - y0) * (y2 - y1));
            if t > lo && t < hi && (t - b).abs() <= (mid - b).abs() {
                return t;
            }
        }
        let [w0, w1] = self.weights;
        let t = lo + (hi - lo) * w0 / (w0 - w1);
        if t > lo && t < hi { t } else { mid }
    }
}
