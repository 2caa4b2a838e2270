//! Adaptive extraction on a two-level lattice ([`super::Extraction::Adaptive`]): cubes of two grid
//! cells where the field is close to linear, split into the grid's own cells where it bends.
//!
//! 1. **Seeds.** The domain is cut into bricks of 8³ coarse cubes (16³ grid cells); a brick that
//!    the [`Region`] and the field's skip test let through is probed in tiles of 2³ cubes (8
//!    corners and the centre); a tile whose probe changes sign has its 27 cube corners evaluated,
//!    and its cubes whose corners change sign are the seeds.
//! 2. **Following and splitting**, in rounds to a fix point: each new cube gets the values and
//!    gradients at its corners and centre, and is split when the field is not close to linear in
//!    it: a corner's gradient more than ~26° off the centre's ([`SPLIT_COS`]; curvature, thin
//!    parts, two sheets in one cube), or the first-order prediction of the centre from a corner
//!    off by more than the tolerance (in distance, `|Δf| / |∇f|`). A split cube has its 27 grid
//!    nodes evaluated. Then every cube whose face nodes (as its tetrahedra use them,
//!    [`super::tets`]) change sign brings in the neighbour across that face, until no face with a
//!    sign change borders a cube left out: the zero set is followed whole from its seeds.
//! 3. **Triangulation.** Marching tetrahedra on the conforming tetrahedra of the cubes
//!    ([`super::tets`]: split cubes 48 Kuhn tetrahedra, the others a cone over their faces), each
//!    vertex placed on its tetrahedron edge by linear interpolation and `refine_steps` safeguarded
//!    root-finding steps ([`super::refine`]), vertices welded by edge, cubes in id order
//!    (deterministic).
//!
//! The mesh is closed, manifold and consistently oriented wherever the zero set is closed inside
//! the followed cubes, like the uniform extractor's; where the field is linear over a cube the
//! mesh has the uniform grid's vertex spacing doubled, elsewhere the uniform grid's resolution.
//! Measured (`examples/extraction.rs`, fields fitted to seven real scans): 34–52 % fewer field
//! values and 12–36 % fewer triangles than the uniform grid, but 1.1–1.6 times its time: the
//! probe, the skip tests and the vertex placement cost what they cost there, an unsplit cube's
//! cone of tetrahedra still makes about 60 % of the fine grid's triangles, and the hash maps and
//! per-round passes cost more than the saved values. What the seeds can miss is
//! what the uniform extractor's probe misses (small isolated bubbles, see
//! [`super::Seeding::SignChange`]), at twice the probe spacing; a sheet thinner than a coarse cube
//! is seen where a cube's corners or centre fall on both sides of it (it also bends the
//! gradients, which splits the cube).

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

use rayon::prelude::*;

use super::grid::Grid;
use super::tets::{self, Node};
use super::{PolygonizeError, PolygonizeParams, PolygonizeStats, Region, RegionField, ScalarField};
use crate::geometry::{Aabb, Point3, TriMesh, dot, norm, sub};
use crate::progress::Progress;
use lattice::{BRICK, FastMap, Lattice, Samples, corners, fine_nodes};
use mesh::{place, triangulate};

mod lattice;
mod mesh;

/// Cosine of the largest angle between a corner's gradient and the centre's in an unsplit cube.
const SPLIT_COS: f64 = 0.9;

/// Extracts the zero set adaptively (see the module documentation); `tolerance` is the largest
/// first-order prediction error (normalised units) an unsplit cube may have.
pub(crate) fn polygonize_adaptive(
    field: &dyn ScalarField,
    domain: &Aabb,
    params: &PolygonizeParams,
    tolerance: f64,
    region: &dyn Region,
    progress: &dyn Progress,
) -> Result<(TriMesh, PolygonizeStats), PolygonizeError> {
    let grid = Grid::new(domain, params)?;
    let lat = Lattice {
        origin: grid.origin,
        h: grid.h,
        cubes: grid.cells.map(|n| n.div_ceil(2) as i64),
    };
    let mut samples = Samples {
        values: FastMap::default(),
        gradients: FastMap::default(),
        prepared: HashMap::new(),
        evaluations: 0,
    };
    let seeds = seeds(field, region, &lat, &mut samples, progress)?;
    progress.fraction(0.2);
    let cubes = follow(
        field,
        region,
        &lat,
        &mut samples,
        seeds,
        tolerance,
        progress,
    )?;
    progress.fraction(0.6);
    let (triangles, edges) = triangulate(field, &lat, &mut samples, &cubes);
    if progress.cancelled() {
        return Err(PolygonizeError::Cancelled);
    }
    progress.fraction(0.8);
    let mesh = place(
        field,
        &lat,
        &mut samples,
        &triangles,
        edges,
        params.refine_steps,
    )?;
    progress.fraction(1.0);
    let b = lat.bricks();
    let active: BTreeSet<[i64; 3]> = (cubes.keys())
        .map(|&id| lat.brick_of(lat.cube_of(id).map(|x| 2 * x + 1)))
        .collect();
    let stats = PolygonizeStats {
        cells_total: grid.cell_count(),
        blocks_total: (b[0] * b[1] * b[2]) as usize,
        blocks_active: active.len(),
        field_evaluations: samples.evaluations,
    };
    Ok((mesh, stats))
}

/// Step 1: the seed cubes (ids, ascending), their corner values stored in `samples`.
fn seeds<'a>(
    field: &'a dyn ScalarField,
    region: &dyn Region,
    lat: &Lattice,
    samples: &mut Samples<'a>,
    progress: &dyn Progress,
) -> Result<Vec<u64>, PolygonizeError> {
    let b = lat.bricks();
    let all: Vec<[i64; 3]> = (0..b[0] * b[1] * b[2])
        .map(|i| [i % b[0], (i / b[0]) % b[1], i / (b[0] * b[1])])
        .collect();
    let found: Vec<Probed<'a>> = all
        .par_iter()
        .filter(|&&br| {
            let bx = lat.brick_box(br);
            !progress.cancelled() && region.touches(&bx) && field.may_contain_zero(&bx)
        })
        .map(|&br| probe_brick(field, region, lat, br))
        .collect();
    if progress.cancelled() {
        return Err(PolygonizeError::Cancelled);
    }
    let mut seeds = Vec::new();
    for (values, s, prepared) in found {
        samples.prepared.extend(prepared);
        for (id, v) in values {
            if samples.values.insert(id, v).is_none() {
                samples.evaluations += 1;
            }
        }
        seeds.extend(s);
    }
    seeds.sort_unstable();
    seeds.dedup();
    Ok(seeds)
}

/// What [`probe_brick`] found: the values evaluated, the seed cubes, the prepared fields of the
/// tiles whose probe changes sign.
type Probed<'a> = (
    Vec<(u64, f64)>,
    Vec<u64>,
    Vec<([i64; 3], Box<dyn RegionField + 'a>)>,
);

/// Probes the tiles (2³ cubes) of brick `br`: the values it evaluated and the cubes whose corners
/// change sign in the tiles whose probe does.
fn probe_brick<'a>(
    field: &'a dyn ScalarField,
    region: &dyn Region,
    lat: &Lattice,
    br: [i64; 3],
) -> Probed<'a> {
    let mut kept = Vec::new();
    let mut known: FastMap<f64> = FastMap::default();
    let eval = |prepared: &mut dyn RegionField, nodes: &[Node], known: &mut FastMap<f64>| {
        let todo: Vec<Node> = (nodes.iter().copied())
            .filter(|n| !known.contains_key(&lat.id(*n)))
            .collect();
        let pts: Vec<Point3> = todo.iter().map(|&n| lat.point(n)).collect();
        let mut v = vec![0.0; pts.len()];
        prepared.values(&pts, &mut v);
        for (n, f) in todo.iter().zip(v) {
            known.insert(lat.id(*n), if f.is_nan() { f64::INFINITY } else { f });
        }
    };
    let lo = br.map(|x| x * BRICK);
    let hi = [0, 1, 2].map(|k| (lo[k] + BRICK).min(lat.cubes[k]));
    let tiles: Vec<[i64; 3]> = cubes_between(lo.map(|x| x / 2), hi.map(|x| (x + 1) / 2))
        .filter(|&t| region.touches(&lat.tile_box(t)))
        .collect();
    let boxes: Vec<Aabb> = tiles.iter().map(|&t| lat.tile_box(t)).collect();
    let mut near = vec![false; tiles.len()];
    field.may_contain_zero_each(&boxes, &mut near);
    let mut seeds = Vec::new();
    for ((t, tile), _) in (tiles.iter().zip(&boxes).zip(&near)).filter(|x| *x.1) {
        let t0 = t.map(|x| 2 * x);
        let t1 = [0, 1, 2].map(|k| (t0[k] + 2).min(hi[k]));
        let mut prepared = field.prepare(tile);
        let mut probe: Vec<Node> = (0..8)
            .map(|m| [0, 1, 2].map(|k| 2 * if m >> k & 1 == 0 { t0[k] } else { t1[k] }))
            .collect();
        probe.push([0, 1, 2].map(|k| t0[k] + t1[k]));
        eval(&mut *prepared, &probe, &mut known);
        let first = known[&lat.id(probe[0])] < 0.0;
        if probe.iter().all(|n| (known[&lat.id(*n)] < 0.0) == first) {
            continue;
        }
        let all: Vec<Node> = (0..27)
            .map(|m| [m % 3, (m / 3) % 3, m / 9])
            .map(|d| [0, 1, 2].map(|k| 2 * (t0[k] + d[k]).min(t1[k])))
            .collect();
        eval(&mut *prepared, &all, &mut known);
        kept.push((*t, prepared));
        for c in cubes_between(t0, t1) {
            let f = corners(c).map(|n| known[&lat.id(n)]);
            if f.iter().any(|&x| (x < 0.0) != (f[0] < 0.0)) && region.touches(&lat.cube_box(c)) {
                seeds.push(lat.cube_id(c));
            }
        }
    }
    (known.into_iter().collect(), seeds, kept)
}

/// The cubes `c` with `t0 ≤ c < t1` per axis.
fn cubes_between(t0: [i64; 3], t1: [i64; 3]) -> impl Iterator<Item = [i64; 3]> {
    (t0[2]..t1[2])
        .flat_map(move |z| (t0[1]..t1[1]).flat_map(move |y| (t0[0]..t1[0]).map(move |x| [x, y, z])))
}

/// Whether the coarse edge between corners `a` and `b` is split: one of the cubes around it is.
fn edge_split(lat: &Lattice, split: &HashSet<u64>, a: Node, b: Node) -> bool {
    tets::cubes_around_edge(a, b).is_some_and(|cubes| {
        (cubes.into_iter()).any(|c| lat.has_cube(c) && split.contains(&lat.cube_id(c)))
    })
}

/// The nodes of face (`axis`, `side` 0 | 2) of cube `c` as its tetrahedra use them
/// ([`tets::face_ring`]; a split cube's edges are all split).
fn face_nodes(
    lat: &Lattice,
    split: &HashSet<u64>,
    c: [i64; 3],
    axis: usize,
    side: i64,
) -> Vec<Node> {
    let se = |a: Node, b: Node| edge_split(lat, split, a, b);
    let (mut nodes, centre) = tets::face_ring(c.map(|x| 2 * x), axis, side, &se);
    nodes.extend(centre);
    nodes
}

/// Step 2: the followed cubes (id → split), to the fix point.
fn follow<'a>(
    field: &'a dyn ScalarField,
    region: &dyn Region,
    lat: &Lattice,
    samples: &mut Samples<'a>,
    mut frontier: Vec<u64>,
    tolerance: f64,
    progress: &dyn Progress,
) -> Result<BTreeMap<u64, bool>, PolygonizeError> {
    let mut cubes: BTreeMap<u64, bool> = BTreeMap::new();
    let mut split: HashSet<u64> = HashSet::new();
    while !frontier.is_empty() {
        if progress.cancelled() {
            return Err(PolygonizeError::Cancelled);
        }
        let nodes: Vec<Node> = (frontier.iter())
            .flat_map(|&id| {
                let c = lat.cube_of(id);
                let mut n = corners(c).to_vec();
                n.push(c.map(|x| 2 * x + 1));
                n
            })
            .collect();
        samples.evaluate(field, lat, &nodes, true);
        let maps = (&samples.values, &samples.gradients);
        let decided: Vec<(u64, bool)> = frontier
            .par_iter()
            .map(|&id| (id, needs_split(lat, maps, lat.cube_of(id), tolerance)))
            .collect();
        let fine: Vec<Node> = (decided.iter().filter(|d| d.1))
            .flat_map(|d| fine_nodes(lat.cube_of(d.0)))
            .collect();
        samples.evaluate(field, lat, &fine, false);
        let mut affected: BTreeSet<u64> = frontier.iter().copied().collect();
        for &(id, is_split) in &decided {
            cubes.insert(id, is_split);
            if is_split {
                split.insert(id);
                let c = lat.cube_of(id);
                for d in cubes_between([-1; 3], [2; 3]) {
                    let n = [0, 1, 2].map(|k| c[k] + d[k]);
                    let along = d.iter().filter(|&&x| x != 0).count();
                    if along <= 2 && lat.has_cube(n) && cubes.contains_key(&lat.cube_id(n)) {
                        affected.insert(lat.cube_id(n));
                    }
                }
            }
        }
        let faces: Vec<([i64; 3], usize, i64, Vec<Node>)> = (affected.iter())
            .flat_map(|&id| {
                let c = lat.cube_of(id);
                (0..3).flat_map(move |a| [0, 2].map(move |s| (c, a, s)))
            })
            .map(|(c, a, s)| (c, a, s, face_nodes(lat, &split, c, a, s)))
            .collect();
        let centres: Vec<Node> = (faces.iter())
            .filter(|f| f.3.len() > 4)
            .map(|f| *f.3.last().unwrap())
            .collect();
        samples.evaluate(field, lat, &centres, false);
        let mut next = BTreeSet::new();
        for (c, a, s, nodes) in &faces {
            let first = samples.value(lat, nodes[0]) < 0.0;
            if nodes
                .iter()
                .all(|&n| (samples.value(lat, n) < 0.0) == first)
            {
                continue;
            }
            let mut n = *c;
            n[*a] += if *s == 0 { -1 } else { 1 };
            if lat.has_cube(n)
                && !cubes.contains_key(&lat.cube_id(n))
                && region.touches(&lat.cube_box(n))
            {
                next.insert(lat.cube_id(n));
            }
        }
        frontier = next.into_iter().collect();
    }
    Ok(cubes)
}

/// Whether cube `c` must be split (see the module documentation).
fn needs_split(
    lat: &Lattice,
    (values, gradients): (&FastMap<f64>, &FastMap<Point3>),
    c: [i64; 3],
    tolerance: f64,
) -> bool {
    let centre = c.map(|x| 2 * x + 1);
    let (xc, fc) = (lat.point(centre), values[&lat.id(centre)]);
    let gc = gradients[&lat.id(centre)];
    let ngc = norm(gc);
    if !(ngc > 0.0 && fc.is_finite()) {
        return true;
    }
    corners(c).iter().any(|&n| {
        let (f, g) = (values[&lat.id(n)], gradients[&lat.id(n)]);
        let ng = norm(g);
        let predicted = f + dot(g, sub(xc, lat.point(n)));
        !(ng > 0.0 && f.is_finite())
            || dot(g, gc) < SPLIT_COS * ng * ngc
            || (predicted - fc).abs() > tolerance * ngc
    })
}
