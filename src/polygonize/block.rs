//! Marching tetrahedra inside one block of the grid: sample the corners of the block's tiles that may
//! hold the zero set (and of every tile it enters from one of those), triangulate the cells of the
//! sampled tiles with the Kuhn case table, and place each vertex on its grid edge (linear interpolation plus a few
//! safeguarded Illinois regula-falsi steps, Dowell & Jarratt 1971).
//!
//! `O(c + v · s)` field evaluations for `c` block corners, `v` vertices and `s` refinement steps.
//! Vertices are keyed by global edge id and computed from the edge's canonical end points, so the same
//! edge gives bit-identical vertices in every block that touches it.

use super::grid::Grid;
use super::kuhn::{CubeEdge, TETS, TetCase};
use super::refine::{EdgeRoot, place_vertices};
use super::{PolygonizeParams, Region, RegionField, ScalarField, Seeding};
use crate::geometry::{Aabb, Point3};

/// How a tile of a block was treated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TileState {
    /// Outside the [`Region`]: not sampled, none of its cells is triangulated.
    Outside,
    /// Ruled out by [`ScalarField::may_contain_zero`] and not demanded by a sampled neighbour: not
    /// sampled, none of its cells is triangulated.
    Skipped,
    /// Every corner evaluated; its cells are triangulated.
    Sampled,
}

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
    /// State of every tile of the block (x fastest).
    pub tiles: Vec<TileState>,
    /// Global tile coordinates (cell index / [`TILE`]) outside this block that must be sampled:
    /// the zero set crosses a cell face they share with a sampled tile of this block.
    pub demands: Vec<[usize; 3]>,
}

/// Inside test: `f < 0`. Zero (and NaN) counts as outside, so no corner lies on the surface.
#[inline]
fn inside(f: f64) -> bool {
    f < 0.0
}

/// Working state of one block.
struct Block<'a> {
    field: &'a dyn ScalarField,
    /// The field prepared for each sampled tile ([`Sampling::prepared`]).
    prepared: Vec<Option<Box<dyn RegionField + 'a>>>,
    region: &'a dyn Region,
    grid: &'a Grid,
    lo: [usize; 3],
    /// Corners per axis (`cells + 1`).
    dims: [usize; 3],
    /// Tiles per axis.
    tiles: [usize; 3],
    values: Vec<f64>,
    /// Local edge slot (`local corner · 7 + dir − 1`) → local vertex index, `u32::MAX` when absent.
    slots: Vec<u32>,
    /// The edge of every vertex, placed once all cells are triangulated.
    roots: Vec<EdgeRoot>,
    /// Local tile of the cell being triangulated.
    tile: usize,
    refine_steps: usize,
    out: BlockMesh,
}

/// Cells per axis of the tiles a block is sampled in (divides the block edge, so tiles are aligned
/// over the whole grid: global tile = global cell / `TILE`).
pub(crate) const TILE: usize = 4;

/// Tiles per axis of a block with `dims` corners per axis.
pub(crate) fn tile_counts(dims: [usize; 3]) -> [usize; 3] {
    [0, 1, 2].map(|a| (dims[a] - 1).div_ceil(TILE).max(1))
}

/// The corners of one block, sampled tile by tile.
///
/// A tile outside `keep` ([`TileState::Outside`]) and a tile the field rules out
/// (`may_contain_zero(tile) == false`, [`TileState::Skipped`]) are not sampled (their corners stay
/// NaN) and none of their cells is triangulated. A skipped tile is sampled after all when the zero
/// set, as seen on the corners of a sampled neighbour, crosses a cell face the two share (a face
/// whose four corners do not all have one sign), and so on until no sampled face with a sign change
/// borders a skipped tile; faces on the block's border give [`BlockMesh::demands`] to the caller.
/// So the skip test is an optimisation only: every piece of the zero set that meets a sampled cell
/// is extracted whole, whatever the test answers (see [`super::extract`]).
struct Sampling<'a> {
    values: Vec<f64>,
    tiles: Vec<TileState>,
    evaluations: u64,
    demands: Vec<[usize; 3]>,
    /// The field prepared for each sampled tile, kept for placing the tile's vertices (one
    /// gather per tile for probe, samples, refinement and normals).
    prepared: Vec<Option<Box<dyn RegionField + 'a>>>,
}

/// Coordinates of local tile `t` (x fastest) of a block with `tiles` tiles per axis.
fn tile_coords(t: usize, tiles: [usize; 3]) -> [usize; 3] {
    [
        t % tiles[0],
        (t / tiles[0]) % tiles[1],
        t / (tiles[0] * tiles[1]),
    ]
}

/// Local corners `[c0, c1]` (inclusive) of tile `t3`.
fn tile_corners(t3: [usize; 3], dims: [usize; 3]) -> ([usize; 3], [usize; 3]) {
    let c0 = t3.map(|a| a * TILE);
    let c1 = [0, 1, 2].map(|a| (c0[a] + TILE).min(dims[a] - 1));
    (c0, c1)
}

/// Closed box of tile `t3` of the block at grid cell `lo` with `dims` corners per axis.
fn tile_region(grid: &Grid, lo: [usize; 3], dims: [usize; 3], t3: [usize; 3]) -> Aabb {
    let (c0, c1) = tile_corners(t3, dims);
    Aabb {
        min: grid.corner([0, 1, 2].map(|a| lo[a] + c0[a])),
        max: grid.corner([0, 1, 2].map(|a| lo[a] + c1[a])),
    }
}

/// Samples the corners of the block at grid cell `lo` with `dims` corners per axis; `forced` lists
/// tiles (local index, x fastest) to sample whatever the skip test says.
fn sample_corners<'a>(
    field: &'a dyn ScalarField,
    keep: &dyn Region,
    grid: &Grid,
    lo: [usize; 3],
    dims: [usize; 3],
    forced: &[usize],
    seeding: Seeding,
) -> Sampling<'a> {
    let tiles = tile_counts(dims);
    let count = tiles[0] * tiles[1] * tiles[2];
    let t3_of = |t: usize| tile_coords(t, tiles);
    let tile_box = |t3: [usize; 3]| tile_region(grid, lo, dims, t3);
    let mut s = Sampling {
        values: vec![f64::NAN; dims.iter().product()],
        tiles: vec![TileState::Skipped; count],
        evaluations: 0,
        demands: Vec::new(),
        prepared: (0..count).map(|_| None).collect(),
    };
    let mut queue = Vec::new();
    let mut asked = (Vec::new(), Vec::new());
    for t in 0..count {
        let region = tile_box(t3_of(t));
        if !keep.touches(&region) {
            s.tiles[t] = TileState::Outside;
        } else if forced.contains(&t) {
            queue.push(t);
        } else {
            asked.0.push(t);
            asked.1.push(region);
        }
    }
    let mut answers = vec![false; asked.0.len()];
    field.may_contain_zero_each(&asked.1, &mut answers);
    let mut scratch = (Vec::new(), Vec::new(), Vec::new());
    if seeding == Seeding::SignChange {
        for (k, &t) in asked.0.iter().enumerate() {
            if answers[k] {
                answers[k] = probe_and_sample(field, grid, (lo, dims), t, &mut s, &mut scratch);
            }
        }
    }
    queue.extend(asked.0.iter().zip(&answers).filter(|a| *a.1).map(|a| *a.0));
    queue.sort_unstable();
    for &t in &queue {
        s.tiles[t] = TileState::Sampled;
    }
    while !queue.is_empty() {
        queue.sort_unstable();
        for &t in &queue {
            s.evaluations += sample_tile(
                &mut s.prepared[t],
                field,
                grid,
                (lo, dims),
                t3_of(t),
                &mut s.values,
                &mut scratch,
            );
        }
        let mut next = Vec::new();
        for &t in &queue {
            for (a, step) in crossed_faces(&s.values, dims, t3_of(t)) {
                let t3 = t3_of(t);
                let n = t3[a] as isize + step;
                if n >= 0 && (n as usize) < tiles[a] {
                    let mut n3 = t3;
                    n3[a] = n as usize;
                    let nt = n3[0] + tiles[0] * (n3[1] + tiles[1] * n3[2]);
                    if s.tiles[nt] == TileState::Skipped {
                        s.tiles[nt] = TileState::Sampled;
                        next.push(nt);
                    }
                } else {
                    let g = (lo[a] / TILE) as isize + n;
                    if g >= 0 && (g as usize) < grid.cells[a].div_ceil(TILE) {
                        let mut g3 = [0, 1, 2].map(|k| lo[k] / TILE + t3[k]);
                        g3[a] = g as usize;
                        s.demands.push(g3);
                    }
                }
            }
        }
        queue = next;
    }
    s.demands.sort_unstable();
    s.demands.dedup();
    s
}

/// [`probe_tile`] on tile `t` (local index) of the block (`lo`, `dims`) and, when the probe
/// changes sign, [`sample_tile`] at once on the same prepared field (kept in `s.prepared`).
fn probe_and_sample<'a>(
    field: &'a dyn ScalarField,
    grid: &Grid,
    (lo, dims): ([usize; 3], [usize; 3]),
    t: usize,
    s: &mut Sampling<'a>,
    scratch: &mut (Vec<Point3>, Vec<f64>, Vec<usize>),
) -> bool {
    let t3 = tile_coords(t, tile_counts(dims));
    let mut prepared = field.prepare(&tile_region(grid, lo, dims, t3));
    if !probe_tile(&mut *prepared, grid, (lo, dims), t3, s, scratch) {
        return false;
    }
    s.prepared[t] = Some(prepared);
    let sampled = sample_tile(
        &mut s.prepared[t],
        field,
        grid,
        (lo, dims),
        t3,
        &mut s.values,
        scratch,
    );
    s.evaluations += sampled;
    true
}

/// Whether the 8 corners and the centre of tile `t3` of the block (`lo`, `dims`) change sign
/// ([`Seeding::SignChange`]); the corners are stored in `s.values` like any sampled corner (the
/// centre is a grid node too, [`TILE`] being even, but is evaluated again if the tile is sampled).
fn probe_tile(
    field: &mut dyn RegionField,
    grid: &Grid,
    (lo, dims): ([usize; 3], [usize; 3]),
    t3: [usize; 3],
    s: &mut Sampling,
    (pts, out, _): &mut (Vec<Point3>, Vec<f64>, Vec<usize>),
) -> bool {
    let (c0, c1) = tile_corners(t3, dims);
    let region = tile_region(grid, lo, dims, t3);
    let idx = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
    let corners = (0..8).map(|m| [0, 1, 2].map(|a| if m >> a & 1 == 0 { c0[a] } else { c1[a] }));
    let unknown: Vec<[usize; 3]> = corners
        .clone()
        .filter(|&c| s.values[idx(c)].is_nan())
        .collect();
    pts.clear();
    pts.push(region.center());
    pts.extend(
        unknown
            .iter()
            .map(|c| grid.corner([0, 1, 2].map(|a| lo[a] + c[a]))),
    );
    out.resize(pts.len(), 0.0);
    field.values(pts, out);
    s.evaluations += pts.len() as u64;
    for (&c, &v) in unknown.iter().zip(&out[1..]) {
        // As in `sample_tile`: a NaN is stored as +inf (outside).
        s.values[idx(c)] = if v.is_nan() { f64::INFINITY } else { v };
    }
    let first = inside(out[0]);
    corners.map(idx).any(|i| inside(s.values[i]) != first)
}

/// Evaluates the not yet known corners of tile `t3` in one call, on `prepared` (the field
/// prepared for the tile; prepared here and kept when `None` and a corner is unknown).
fn sample_tile<'a>(
    prepared: &mut Option<Box<dyn RegionField + 'a>>,
    field: &'a dyn ScalarField,
    grid: &Grid,
    (lo, dims): ([usize; 3], [usize; 3]),
    t3: [usize; 3],
    values: &mut [f64],
    (pts, out, slots): &mut (Vec<Point3>, Vec<f64>, Vec<usize>),
) -> u64 {
    let (c0, c1) = tile_corners(t3, dims);
    let idx = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
    let region = tile_region(grid, lo, dims, t3);
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
    if pts.is_empty() {
        return 0;
    }
    out.resize(pts.len(), 0.0);
    prepared
        .get_or_insert_with(|| field.prepare(&region))
        .values(pts, out);
    for (&s, &v) in slots.iter().zip(out.iter()) {
        // A NaN from the field is stored as +inf: outside, and never re-evaluated.
        values[s] = if v.is_nan() { f64::INFINITY } else { v };
    }
    pts.len() as u64
}

/// The faces of sampled tile `t3` (as `(axis, −1 | +1)`) on which some cell face has corners of
/// both signs: the zero set crosses into the neighbouring tile there.
fn crossed_faces(values: &[f64], dims: [usize; 3], t3: [usize; 3]) -> Vec<(usize, isize)> {
    let (c0, c1) = tile_corners(t3, dims);
    let idx = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
    let mut faces = Vec::new();
    for a in 0..3 {
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        for (plane, step) in [(c0[a], -1), (c1[a], 1)] {
            let mut c = [0; 3];
            c[a] = plane;
            let crossed = (c0[u]..c1[u]).any(|i| {
                (c0[v]..c1[v]).any(|j| {
                    let mut signs = [false; 4];
                    for (n, (di, dj)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                        c[u] = i + di;
                        c[v] = j + dj;
                        signs[n] = inside(values[idx(c)]);
                    }
                    signs.iter().any(|&x| x != signs[0])
                })
            });
            if crossed {
                faces.push((a, step));
            }
        }
    }
    faces
}

/// Extracts the zero set inside block `b` of `grid`, sampling the tiles in `forced` (local tile
/// indices) whatever the skip test says.
pub(crate) fn extract_block(
    field: &dyn ScalarField,
    region: &dyn Region,
    grid: &Grid,
    table: &[[TetCase; 16]; 6],
    b: usize,
    params: &PolygonizeParams,
    forced: &[usize],
) -> BlockMesh {
    let (lo, hi) = grid.block_cells(b);
    let dims = [0, 1, 2].map(|k| hi[k] - lo[k] + 1);
    let sampled = sample_corners(field, region, grid, lo, dims, forced, params.seeding);
    let out = BlockMesh {
        evaluations: sampled.evaluations,
        tiles: sampled.tiles,
        demands: sampled.demands,
        ..BlockMesh::default()
    };
    let values = sampled.values;
    let first = values.first().is_some_and(|&f| inside(f));
    if values.iter().all(|&f| inside(f) == first) {
        return out;
    }
    let mut block = Block {
        field,
        prepared: sampled.prepared,
        region,
        grid,
        lo,
        dims,
        tiles: tile_counts(dims),
        slots: vec![u32::MAX; values.len() * 7],
        values,
        roots: Vec::new(),
        tile: 0,
        refine_steps: params.refine_steps,
        out,
    };
    for k in 0..dims[2] - 1 {
        for j in 0..dims[1] - 1 {
            for i in 0..dims[0] - 1 {
                let t = i / TILE + block.tiles[0] * (j / TILE + block.tiles[1] * (k / TILE));
                if block.out.tiles[t] == TileState::Sampled {
                    block.tile = t;
                    block.cell([i, j, k], table);
                }
            }
        }
    }
    block.place_vertices();
    block.out
}

impl Block<'_> {
    /// Places every vertex on its edge, the vertices of one tile together
    /// ([`place_vertices`]).
    fn place_vertices(&mut self) {
        let mut order: Vec<u32> = (0..self.roots.len() as u32).collect();
        order.sort_by_key(|&v| self.roots[v as usize].tile);
        let t3_of = |t: usize| tile_coords(t, self.tiles);
        for group in
            order.chunk_by(|a, b| self.roots[*a as usize].tile == self.roots[*b as usize].tile)
        {
            let roots: Vec<EdgeRoot> = group.iter().map(|&v| self.roots[v as usize]).collect();
            let region = tile_region(self.grid, self.lo, self.dims, t3_of(roots[0].tile));
            let mut prepared = (self.prepared[roots[0].tile].take())
                .unwrap_or_else(|| self.field.prepare(&region));
            let (positions, normals, evaluations) =
                place_vertices(&mut *prepared, &roots, self.refine_steps);
            for ((&v, p), n) in group.iter().zip(positions).zip(normals) {
                self.out.positions[v as usize] = p;
                self.out.normals[v as usize] = n;
            }
            self.out.evaluations += evaluations;
        }
    }

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
        let index = self.out.positions.len() as u32;
        self.out.positions.push(p_in);
        self.out.normals.push([0.0; 3]);
        self.roots.push(EdgeRoot {
            p_in,
            f_in,
            p_out,
            f_out,
            tile: self.tile,
        });
        self.out
            .edge_ids
            .push(self.grid.corner_id(ga) * 7 + dir as u64 - 1);
        self.slots[slot] = index;
        index
    }
}
