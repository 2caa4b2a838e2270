//! Sparse, parallel, watertight extraction of a field's zero set: the polygonizer's entry point.
//!
//! The domain is covered by a grid of cubic cells split into blocks of 16³ cells, sampled in tiles of
//! 4³ cells. Only blocks and tiles for which [`ScalarField::may_contain_zero`] answers true are
//! considered (the narrow band); with the default [`super::Seeding::SignChange`] such a tile is
//! sampled only when its 8 corners and centre change sign. From the sampled tiles, every skipped
//! tile the zero set enters through a cell face of a sampled tile (a face whose corners have both
//! signs) is sampled too, repeated across tiles and blocks to a fix point. So the mesh is exactly
//! the one without any skipping, vertex for vertex, except for connected pieces of the zero set
//! that meet no sampled tile: with [`super::Seeding::EveryTile`] pieces lying entirely in tiles the
//! skip test ruled out (for the fitted fields, farther than the support radius from every data
//! point, [`crate::rbf::RbfField`]: floaters that carry no data); with the sign-change seeding also
//! small isolated bubbles (see [`super::Seeding`]). Each block is triangulated
//! in parallel (rayon) by marching tetrahedra on the Kuhn 6-tetrahedra split (Doi & Koide 1991, "An
//! efficient method of triangulating equi-valued surfaces by using tetrahedral cells"), which — unlike
//! 256-case marching cubes (Lorensen & Cline 1987) — has no ambiguous faces, so the result is closed,
//! edge- and vertex-manifold and consistently oriented wherever the zero set is closed inside the domain.
//! Vertices are welded across cells and blocks by global grid-edge id.
//!
//! [`polygonize_in`] restricts the extraction to a [`Region`] (e.g. the band the data support on an
//! open scan): blocks and tiles outside it are neither sampled nor triangulated, and a cell is
//! triangulated only when its box touches the region. Inside the region the mesh is exactly the one
//! [`polygonize`] gives (same grid, same vertices); it ends, open, at cell faces on the region's border.
//!
//! Cost: one field evaluation per corner of each sampled tile plus `refine_steps + 1` per vertex
//! (value and gradient), `O(active cells)` work and memory.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use super::block::{BlockMesh, TileState, extract_block};
use super::grid::Grid;
use super::kuhn::case_table;
use super::params::{PolygonizeError, PolygonizeParams, PolygonizeStats};
use super::{Everywhere, Region, ScalarField};
use crate::geometry::{Aabb, TriMesh};
use crate::progress::Progress;

/// Share of the progress bar spent on the narrow-band test.
const CLASSIFY_SHARE: f64 = 0.05;

/// Extracts the zero set of `field` inside `domain` (normalised units) as a triangle mesh with unit
/// outward vertex normals, counter-clockwise seen from outside (`f > 0`).
///
/// The mesh is closed where the zero set is closed inside the domain; the caller should make the field
/// positive on the domain boundary (otherwise the mesh is open there). Reports `progress.fraction` and
/// stops with [`PolygonizeError::Cancelled`] soon after `progress.cancelled()` turns true.
///
/// # Errors
/// [`PolygonizeError::ZeroResolution`], [`PolygonizeError::EmptyDomain`],
/// [`PolygonizeError::GridTooLarge`] (checked before allocating), [`PolygonizeError::TooManyVertices`],
/// [`PolygonizeError::Cancelled`].
///
/// # Example
/// ```
/// use rbfsurf::geometry::{norm, scale, Aabb, Point3};
/// use rbfsurf::polygonize::{polygonize, PolygonizeParams, ScalarField};
/// struct Ball;
/// impl ScalarField for Ball {
///     fn value(&self, p: &Point3) -> f64 { norm(*p) - 0.5 }
///     fn gradient(&self, p: &Point3) -> Point3 { scale(*p, 1.0 / norm(*p)) }
///     fn may_contain_zero(&self, _cell: &Aabb) -> bool { true }
/// }
/// let domain = Aabb { min: [-1.0; 3], max: [1.0; 3] };
/// let params = PolygonizeParams { resolution: 16, ..Default::default() };
/// let (mesh, stats) = polygonize(&Ball, &domain, &params, &rbfsurf::progress::NoProgress).unwrap();
/// assert!(rbfsurf::mesh::analyze(&mesh).watertight);
/// assert_eq!(stats.cells_total, 16 * 16 * 16);
/// ```
pub fn polygonize(
    field: &dyn ScalarField,
    domain: &Aabb,
    params: &PolygonizeParams,
    progress: &dyn Progress,
) -> Result<(TriMesh, PolygonizeStats), PolygonizeError> {
    polygonize_in(field, domain, params, &Everywhere, progress)
}

/// [`polygonize`] restricted to the cells whose box touches `region` (see [`Region`]): the same
/// vertices and triangles in those cells, nothing elsewhere, and nothing sampled in blocks or tiles
/// outside the region. Deterministic (the region is asked about boxes only).
///
/// # Errors
/// As [`polygonize`].
pub fn polygonize_in(
    field: &dyn ScalarField,
    domain: &Aabb,
    params: &PolygonizeParams,
    region: &dyn Region,
    progress: &dyn Progress,
) -> Result<(TriMesh, PolygonizeStats), PolygonizeError> {
    let grid = Grid::new(domain, params)?;
    let table = case_table();
    let blocks_total = grid.block_count();
    let active: Vec<usize> = (0..blocks_total)
        .into_par_iter()
        .filter(|&b| {
            let bbox = grid.block_box(b);
            !progress.cancelled() && region.touches(&bbox) && field.may_contain_zero(&bbox)
        })
        .collect();
    if progress.cancelled() {
        return Err(PolygonizeError::Cancelled);
    }
    progress.fraction(CLASSIFY_SHARE);
    let done = AtomicUsize::new(0);
    let report_every = (active.len() / 200).max(1);
    let mut meshes: BTreeMap<usize, BlockMesh> = BTreeMap::new();
    let mut forced: HashMap<usize, Vec<usize>> = HashMap::new();
    let mut todo = active;
    while !todo.is_empty() {
        let expected = todo.len().max(report_every);
        let round: Vec<(usize, BlockMesh)> = todo
            .par_iter()
            .map(|&b| {
                if progress.cancelled() {
                    return Err(PolygonizeError::Cancelled);
                }
                let tiles = forced.get(&b).map_or(&[][..], Vec::as_slice);
                let mesh = extract_block(field, region, &grid, &table, b, params, tiles);
                let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
                if finished.is_multiple_of(report_every) {
                    let share = (finished as f64 / expected as f64).min(1.0);
                    progress.fraction(CLASSIFY_SHARE + (0.95 - CLASSIFY_SHARE) * share);
                }
                Ok((b, mesh))
            })
            .collect::<Result<_, _>>()?;
        let processed: Vec<usize> = round.iter().map(|(b, _)| *b).collect();
        meshes.extend(round);
        todo = demanded_blocks(&grid, region, &meshes, &processed, &mut forced);
    }
    let meshes: Vec<BlockMesh> = meshes.into_values().collect();
    let mesh = weld(&meshes)?;
    progress.fraction(1.0);
    let stats = PolygonizeStats {
        cells_total: grid.cell_count(),
        blocks_total,
        blocks_active: meshes.len(),
        field_evaluations: meshes.iter().map(|m| m.evaluations).sum(),
    };
    Ok((mesh, stats))
}

/// The blocks to (re-)extract because a block of `processed` found the zero set crossing into one
/// of their tiles that is not sampled yet (skipped, or the block was not extracted at all); the
/// tiles are added to `forced`. Blocks outside `region` are never demanded. Ascending, so each
/// round, and the fix point, do not depend on the thread schedule.
fn demanded_blocks(
    grid: &Grid,
    region: &dyn Region,
    meshes: &BTreeMap<usize, BlockMesh>,
    processed: &[usize],
    forced: &mut HashMap<usize, Vec<usize>>,
) -> Vec<usize> {
    let mut next = BTreeSet::new();
    for b in processed {
        for &g in &meshes[b].demands {
            let (nb, tile) = grid.tile_home(g);
            match meshes.get(&nb) {
                Some(m) if m.tiles[tile] != TileState::Skipped => continue,
                None if !region.touches(&grid.block_box(nb)) => continue,
                _ => {}
            }
            let tiles = forced.entry(nb).or_default();
            if !tiles.contains(&tile) {
                tiles.push(tile);
                next.insert(nb);
            }
        }
    }
    next.into_iter().collect()
}

/// Multiplicative hasher for the (already well-spread) edge ids.
#[derive(Default)]
struct EdgeIdHasher(u64);

impl Hasher for EdgeIdHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0100_0000_01B3);
        }
    }
    fn write_u64(&mut self, x: u64) {
        let z = (x ^ (x >> 31)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = z ^ (z >> 29);
    }
}

/// Concatenates the block meshes in block order, merging vertices with the same global edge id.
fn weld(blocks: &[BlockMesh]) -> Result<TriMesh, PolygonizeError> {
    let upper: usize = blocks.iter().map(|b| b.positions.len()).sum();
    let triangles: usize = blocks.iter().map(|b| b.triangles.len()).sum();
    let mut ids: HashMap<u64, u32, BuildHasherDefault<EdgeIdHasher>> =
        HashMap::with_capacity_and_hasher(upper, Default::default());
    let mut mesh = TriMesh {
        vertices: Vec::with_capacity(upper),
        normals: Vec::with_capacity(upper),
        triangles: Vec::with_capacity(triangles),
        colors: Vec::new(),
    };
    let mut to_global: Vec<u32> = Vec::new();
    for block in blocks {
        to_global.clear();
        for (i, &id) in block.edge_ids.iter().enumerate() {
            let next = mesh.vertices.len();
            let global = *ids.entry(id).or_insert_with(|| {
                mesh.vertices.push(block.positions[i]);
                mesh.normals.push(block.normals[i]);
                next as u32
            });
            if mesh.vertices.len() > u32::MAX as usize {
                return Err(PolygonizeError::TooManyVertices {
                    vertices: mesh.vertices.len(),
                });
            }
            to_global.push(global);
        }
        mesh.triangles.extend(
            block
                .triangles
                .iter()
                .map(|t| t.map(|v| to_global[v as usize])),
        );
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Point3, cross, dot, norm, normalized, scale, sub};
    use crate::mesh::{MeshTopology, analyze, signed_volume};
    use crate::progress::{CancelFlag, NoProgress};
    use std::f64::consts::PI;
    use std::sync::Mutex;

    /// Analytic test shapes; every value is 1-Lipschitz, so `|f(centre)| ≤ half-diagonal` is a
    /// conservative narrow-band test.
    #[derive(Clone, Copy)]
    enum Shape {
        Sphere {
            c: Point3,
            r: f64,
        },
        Torus {
            big: f64,
            small: f64,
        },
        TwoSpheres {
            r: f64,
            gap: f64,
        },
        /// `min(a) · (|D (p − c)| − 1)`, `D = diag(1 / a)`.
        Ellipsoid {
            a: Point3,
        },
        /// A ball cut flat by the plane `z = z0` (kept below).
        HalfBall {
            r: f64,
            z0: f64,
        },
    }

    struct Field {
        shape: Shape,
        band: bool,
    }

    fn sphere(p: Point3, c: Point3, r: f64) -> (f64, Point3) {
        let d = sub(p, c);
        (norm(d) - r, normalized(d).unwrap_or([0.0; 3]))
    }

    impl Shape {
        fn eval(&self, p: Point3) -> (f64, Point3) {
            match *self {
                Shape::Sphere { c, r } => sphere(p, c, r),
                Shape::Torus { big, small } => {
                    let rho = (p[0] * p[0] + p[1] * p[1]).sqrt();
                    let q = [rho - big, p[2]];
                    let d = (q[0] * q[0] + q[1] * q[1]).sqrt();
                    let g = [q[0] * p[0] / (rho * d), q[0] * p[1] / (rho * d), p[2] / d];
                    (d - small, g)
                }
                Shape::TwoSpheres { r, gap } => {
                    let a = sphere(p, [-gap, 0.0, 0.0], r);
                    let b = sphere(p, [gap, 0.0, 0.0], r);
                    if a.0 <= b.0 { a } else { b }
                }
                Shape::Ellipsoid { a } => {
                    let m = a[0].min(a[1]).min(a[2]);
                    let q = [p[0] / a[0], p[1] / a[1], p[2] / a[2]];
                    let n = norm(q);
                    let g = [0, 1, 2].map(|k| m * q[k] / (a[k] * n));
                    (m * (n - 1.0), g)
                }
                Shape::HalfBall { r, z0 } => {
                    let s = sphere(p, [0.0; 3], r);
                    if p[2] - z0 >= s.0 {
                        (p[2] - z0, [0.0, 0.0, 1.0])
                    } else {
                        s
                    }
                }
            }
        }
    }

    impl ScalarField for Field {
        fn value(&self, p: &Point3) -> f64 {
            self.shape.eval(*p).0
        }
        fn gradient(&self, p: &Point3) -> Point3 {
            self.shape.eval(*p).1
        }
        fn may_contain_zero(&self, cell: &Aabb) -> bool {
            !self.band || self.value(&cell.center()).abs() <= 0.5 * cell.diagonal() * (1.0 + 1e-9)
        }
    }

    fn cube(half: f64) -> Aabb {
        Aabb {
            min: [-half; 3],
            max: [half; 3],
        }
    }

    fn run(shape: Shape, resolution: usize, band: bool) -> (TriMesh, PolygonizeStats) {
        let params = PolygonizeParams {
            resolution,
            ..Default::default()
        };
        polygonize(&Field { shape, band }, &cube(1.0), &params, &NoProgress).unwrap()
    }

    /// Closed, manifold, oriented; the same mesh without the narrow band; outward faces; vertices on the
    /// surface with analytic normals.
    /// Largest and mean `|f|` over the vertices.
    fn residuals(shape: Shape, mesh: &TriMesh) -> (f64, f64) {
        let r: Vec<f64> = mesh
            .vertices
            .iter()
            .map(|p| shape.eval(*p).0.abs())
            .collect();
        (
            r.iter().fold(0.0, |a, &b| a.max(b)),
            r.iter().sum::<f64>() / r.len() as f64,
        )
    }

    fn check_closed(shape: Shape, resolution: usize) -> (TriMesh, MeshTopology) {
        let (mesh, stats) = run(shape, resolution, true);
        let topo = analyze(&mesh);
        assert!(
            topo.watertight && topo.manifold && topo.oriented,
            "{topo:?}"
        );
        let (full, full_stats) = run(shape, resolution, false);
        assert_eq!(mesh, full, "the narrow band changed the mesh");
        assert!(stats.blocks_active <= full_stats.blocks_active);
        assert_eq!(full_stats.blocks_active, full_stats.blocks_total);
        assert_eq!(mesh.normals.len(), mesh.vertices.len());
        // All shapes are (near-)distance fields: |f| bounds the distance to the surface, in units of h.
        let h = 2.0 / resolution as f64;
        let (worst, mean) = residuals(shape, &mesh);
        assert!(
            worst <= 0.02 * h && mean <= 1e-4 * h,
            "residual worst {worst}, mean {mean}"
        );
        for (p, n) in mesh.vertices.iter().zip(&mesh.normals) {
            let g = shape.eval(*p).1;
            assert!(dot(*n, normalized(g).unwrap()) > 1.0 - 1e-9);
        }
        let (mut aligned, mut total) = (0.0, 0.0);
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|v| mesh.vertices[v as usize]);
            let n = cross(sub(b, a), sub(c, a));
            let centroid = scale([0, 1, 2].map(|k| a[k] + b[k] + c[k]), 1.0 / 3.0);
            let g = normalized(shape.eval(centroid).1).unwrap();
            // Zero-area triangles (vertices that met at a grid node where f = 0) may have any sign.
            assert!(
                dot(n, g) >= -1e-20,
                "inward triangle {t:?}: {a:?} {b:?} {c:?}"
            );
            aligned += dot(n, g);
            total += norm(n);
        }
        assert!(aligned > 0.99 * total, "{aligned} / {total}");
        (mesh, topo)
    }

    fn assert_close(value: f64, exact: f64, rel: f64) {
        assert!(
            (value - exact).abs() <= rel * exact.abs(),
            "{value} vs {exact}"
        );
    }

    #[test]
    fn sphere_is_a_closed_genus_zero_surface() {
        let (c, r) = ([0.1, -0.05, 0.02], 0.7);
        let (mesh, topo) = check_closed(Shape::Sphere { c, r }, 40);
        assert_eq!((topo.euler, topo.genus, topo.components), (2, Some(0), 1));
        assert_close(signed_volume(&mesh), 4.0 / 3.0 * PI * r.powi(3), 0.01);
    }

    #[test]
    fn torus_has_genus_one() {
        let (big, small) = (0.6, 0.25);
        let (mesh, topo) = check_closed(Shape::Torus { big, small }, 48);
        assert_eq!((topo.euler, topo.genus, topo.components), (0, Some(1), 1));
        assert_close(
            signed_volume(&mesh),
            2.0 * PI * PI * big * small * small,
            0.02,
        );
    }

    #[test]
    fn two_spheres_are_two_components() {
        let r = 0.35;
        let (mesh, topo) = check_closed(Shape::TwoSpheres { r, gap: 0.5 }, 40);
        assert_eq!((topo.euler, topo.genus, topo.components), (4, Some(0), 2));
        assert_close(signed_volume(&mesh), 8.0 / 3.0 * PI * r.powi(3), 0.02);
    }

    #[test]
    fn ellipsoid_is_closed_and_accurate() {
        let a = [0.8, 0.5, 0.3];
        let (mesh, topo) = check_closed(Shape::Ellipsoid { a }, 40);
        assert_eq!((topo.euler, topo.genus), (2, Some(0)));
        assert_close(
            signed_volume(&mesh),
            4.0 / 3.0 * PI * a[0] * a[1] * a[2],
            0.02,
        );
    }

    #[test]
    fn zero_on_grid_nodes_stays_manifold() {
        // h = 2 / 32 = 1/16, so z = 0.5 and the ball's poles at ±0.75 are exactly on grid nodes.
        let shape = Shape::HalfBall { r: 0.75, z0: 0.5 };
        let (mesh, _) = run(shape, 32, true);
        let topo = analyze(&mesh);
        assert!(
            topo.watertight && topo.manifold && topo.oriented,
            "{topo:?}"
        );
        assert_eq!((topo.euler, topo.genus, topo.components), (2, Some(0), 1));
        assert!(signed_volume(&mesh) > 0.0);
        let (worst, _) = residuals(shape, &mesh);
        assert!(worst < 1e-3 / 16.0, "{worst}");
        assert_eq!(mesh, run(shape, 32, false).0);
    }

    #[test]
    fn narrow_band_skips_blocks_and_refinement_helps() {
        let shape = Shape::Sphere {
            c: [0.0; 3],
            r: 0.3,
        };
        let (mesh, stats) = run(shape, 64, true);
        assert_eq!((stats.cells_total, stats.blocks_total), (64 * 64 * 64, 64));
        assert_eq!(stats.blocks_active, 8);
        // Tiles of the active blocks that miss the sphere are not sampled either.
        assert!(stats.field_evaluations < 8 * 17 * 17 * 17, "{stats:?}");
        let params = PolygonizeParams {
            resolution: 64,
            refine_steps: 0,
            ..Default::default()
        };
        let field = Field { shape, band: true };
        let (linear, lstats) = polygonize(&field, &cube(1.0), &params, &NoProgress).unwrap();
        assert!(lstats.field_evaluations < stats.field_evaluations);
        assert_eq!(linear.triangles, mesh.triangles);
        let (refined, linear) = (residuals(shape, &mesh), residuals(shape, &linear));
        assert!(
            refined.1 < 0.01 * linear.1,
            "mean residual {refined:?} vs {linear:?}"
        );
        assert!(
            refined.0 < linear.0,
            "worst residual {refined:?} vs {linear:?}"
        );
    }

    #[test]
    fn surface_leaving_the_domain_gives_an_open_manifold_mesh() {
        let shape = Shape::Sphere {
            c: [0.0; 3],
            r: 1.2,
        };
        let (mesh, _) = run(shape, 24, true);
        let topo = analyze(&mesh);
        assert!(
            !topo.watertight && topo.manifold && topo.oriented,
            "{topo:?}"
        );
        // The sphere pokes through all 6 faces: one surface with 6 holes, χ = 2 − 6.
        assert_eq!(
            (topo.components, topo.boundary_loops, topo.euler),
            (1, 6, -4)
        );
    }

    /// Keeps the boxes that reach below `z = 0` (monotone).
    struct Below;
    impl Region for Below {
        fn touches(&self, cell: &Aabb) -> bool {
            cell.min[2] < 0.0
        }
    }

    #[test]
    fn a_region_keeps_exactly_the_full_mesh_in_its_cells() {
        let shape = Shape::Sphere {
            c: [0.01, -0.02, 0.03],
            r: 0.6,
        };
        let params = PolygonizeParams {
            resolution: 32,
            ..Default::default()
        };
        let field = Field { shape, band: true };
        let (full, fs) = polygonize(&field, &cube(1.0), &params, &NoProgress).unwrap();
        let (part, ps) = polygonize_in(&field, &cube(1.0), &params, &Below, &NoProgress).unwrap();
        assert!(ps.blocks_active < fs.blocks_active, "{ps:?} {fs:?}");
        assert!(ps.field_evaluations < fs.field_evaluations);
        // Every kept triangle is a triangle of the full mesh (same positions), and the full mesh's
        // triangles whose cells lie below z = 0 (all corners below the first grid plane ≥ 0) are kept.
        let key = |m: &TriMesh, t: &[u32; 3]| {
            let mut k = t.map(|v| m.vertices[v as usize].map(f64::to_bits));
            k.sort();
            k
        };
        let full_set: std::collections::HashSet<_> =
            full.triangles.iter().map(|t| key(&full, t)).collect();
        assert!(
            part.triangles
                .iter()
                .all(|t| full_set.contains(&key(&part, t)))
        );
        let part_set: std::collections::HashSet<_> =
            part.triangles.iter().map(|t| key(&part, t)).collect();
        let h = 2.0 / 32.0;
        for t in &full.triangles {
            let top = t
                .iter()
                .map(|&v| full.vertices[v as usize][2])
                .fold(-1.0, f64::max);
            if top < -1e-12 {
                assert!(part_set.contains(&key(&full, t)));
            }
            let bottom = t
                .iter()
                .map(|&v| full.vertices[v as usize][2])
                .fold(1.0, f64::min);
            if bottom > h + 1e-12 {
                assert!(!part_set.contains(&key(&full, t)));
            }
        }
        // A cap cut along a grid plane: one open, manifold, oriented disk.
        let topo = analyze(&part);
        assert!(
            !topo.watertight && topo.manifold && topo.oriented,
            "{topo:?}"
        );
        assert_eq!(
            (topo.components, topo.boundary_loops, topo.euler),
            (1, 1, 1)
        );
    }

    /// Wrong on purpose: says "no zero here" for every box whose centre lies beyond `x = 0.2`.
    struct Liar(Field);
    impl ScalarField for Liar {
        fn value(&self, p: &Point3) -> f64 {
            self.0.value(p)
        }
        fn gradient(&self, p: &Point3) -> Point3 {
            self.0.gradient(p)
        }
        fn may_contain_zero(&self, cell: &Aabb) -> bool {
            cell.center()[0] <= 0.2 && self.0.may_contain_zero(cell)
        }
    }

    #[test]
    fn a_wrong_skip_test_loses_only_pieces_it_hides_entirely() {
        let params = PolygonizeParams {
            resolution: 40,
            ..Default::default()
        };
        // A sphere reaching into the hidden half is followed there from the sampled tiles: the
        // mesh is the honest one, vertex for vertex.
        let shape = Shape::Sphere {
            c: [0.0; 3],
            r: 0.6,
        };
        let liar = Liar(Field { shape, band: true });
        let (mesh, _) = polygonize(&liar, &cube(1.0), &params, &NoProgress).unwrap();
        let (honest, _) = run(shape, 40, true);
        assert_eq!(mesh, honest);
        // A sphere entirely inside hidden tiles is lost; the other one is exact.
        let shape = Shape::TwoSpheres { r: 0.2, gap: 0.6 };
        let liar = Liar(Field { shape, band: true });
        let (mesh, _) = polygonize(&liar, &cube(1.0), &params, &NoProgress).unwrap();
        let (honest, _) = run(shape, 40, true);
        let topo = analyze(&mesh);
        assert_eq!((topo.components, topo.watertight), (1, true));
        let key = |m: &TriMesh, t: &[u32; 3]| {
            let mut k = t.map(|v| m.vertices[v as usize].map(f64::to_bits));
            k.sort();
            k
        };
        let mut left: Vec<_> = (honest.triangles.iter())
            .filter(|t| honest.vertices[t[0] as usize][0] < 0.0)
            .map(|t| key(&honest, t))
            .collect();
        let mut got: Vec<_> = mesh.triangles.iter().map(|t| key(&mesh, t)).collect();
        left.sort();
        got.sort();
        assert_eq!(got, left);
    }

    struct Recorder(Mutex<Vec<f64>>);
    impl Progress for Recorder {
        fn stage(&self, _: crate::progress::Stage) {}
        fn fraction(&self, done: f64) {
            self.0.lock().unwrap().push(done);
        }
        fn cancelled(&self) -> bool {
            false
        }
    }

    #[test]
    fn progress_errors_and_cancellation() {
        let field = Field {
            shape: Shape::Sphere {
                c: [0.0; 3],
                r: 0.5,
            },
            band: true,
        };
        let rec = Recorder(Mutex::new(Vec::new()));
        let params = PolygonizeParams {
            resolution: 20,
            ..Default::default()
        };
        polygonize(&field, &cube(1.0), &params, &rec).unwrap();
        let seen = rec.0.into_inner().unwrap();
        assert!(seen.iter().all(|f| (0.0..=1.0).contains(f)) && seen.last() == Some(&1.0));
        let flag = CancelFlag::default();
        flag.cancel();
        assert_eq!(
            polygonize(&field, &cube(1.0), &params, &flag),
            Err(PolygonizeError::Cancelled)
        );
        let zero = PolygonizeParams {
            resolution: 0,
            ..params
        };
        assert_eq!(
            polygonize(&field, &cube(1.0), &zero, &NoProgress),
            Err(PolygonizeError::ZeroResolution)
        );
        for bad in [
            Aabb::empty(),
            cube(0.0),
            Aabb {
                min: [0.0; 3],
                max: [f64::NAN; 3],
            },
        ] {
            assert!(matches!(
                polygonize(&field, &bad, &params, &NoProgress),
                Err(PolygonizeError::EmptyDomain { .. })
            ));
        }
        let huge = PolygonizeParams {
            resolution: 10_000_000,
            ..params
        };
        assert_eq!(
            polygonize(&field, &cube(1.0), &huge, &NoProgress),
            Err(PolygonizeError::GridTooLarge {
                cells: 1_000_000_000_000_000_000_000u128.min(u64::MAX as u128) as u64,
                limit: 1 << 32
            })
        );
        // A flat domain still gets one layer of cells.
        let flat = Aabb {
            min: [-1.0, -1.0, 0.0],
            max: [1.0, 1.0, 0.0],
        };
        let (_, stats) = polygonize(&field, &flat, &params, &NoProgress).unwrap();
        assert_eq!(stats.cells_total, 400);
    }
}
