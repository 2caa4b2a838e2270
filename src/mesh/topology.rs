//! Topology of a triangle mesh: connected components, watertightness, edge- and vertex-manifoldness,
//! consistent orientation, Euler characteristic and genus; plus signed volume and surface area.
//!
//! Purely combinatorial (indices only, positions are never compared), so welded-but-coincident vertices
//! count as distinct. Complexity `O(F log F)` for `F` triangles (one sort of the half-edges, one sort per
//! vertex fan). Definitions follow the usual surface-topology conventions (e.g. Botsch et al.,
//! *Polygon Mesh Processing*, 2010, ch. 1): `χ = V − E + F` and `g = (2 − χ) / 2` per closed orientable
//! component.

use rayon::prelude::*;
use serde::Serialize;

use super::incidence::{ByVertex, UnionFind, vertex_triangles};
use crate::geometry::{Point3, TriMesh, cross, dot, norm};

/// Topological summary of a triangle mesh (the `"mesh"` object of the JSON report).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct MeshTopology {
    /// Number of distinct vertices referenced by at least one triangle.
    pub vertices: usize,
    /// Number of triangles.
    pub triangles: usize,
    /// Number of undirected edges.
    pub edges: usize,
    /// Connected components of triangles (two triangles are connected when they share a vertex).
    pub components: usize,
    /// True when the mesh has at least one triangle and every undirected edge is used by exactly 2 triangles.
    pub watertight: bool,
    /// True when no edge is used by more than 2 triangles, every vertex's triangles form one fan
    /// (a disk or a half-disk), and no triangle repeats a vertex index.
    pub manifold: bool,
    /// True when no directed edge occurs twice, i.e. every edge shared by two triangles is traversed in
    /// opposite directions by them (consistent winding).
    pub oriented: bool,
    /// Edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Connected components of the graph formed by the boundary edges (holes, for a manifold mesh).
    pub boundary_loops: usize,
    /// Edges used by three or more triangles.
    pub non_manifold_edges: usize,
    /// Vertices whose incident triangles split into more than one edge-connected fan (e.g. a bow-tie).
    pub non_manifold_vertices: usize,
    /// Triangles that repeat a vertex index.
    pub degenerate_triangles: usize,
    /// Euler characteristic `V − E + F` (counting only referenced vertices).
    pub euler: i64,
    /// Total genus `Σ_c (2 − χ_c) / 2` over the components when the mesh is closed, manifold and
    /// oriented; `None` otherwise (and for an empty mesh).
    pub genus: Option<i64>,
}

impl MeshTopology {
    /// The genus as printed for people: the number, or `-` where it is undefined (open,
    /// non-manifold or empty meshes).
    pub fn genus_label(&self) -> String {
        self.genus
            .map_or_else(|| "-".to_string(), |g| g.to_string())
    }
}

/// Per triangle, the index of its connected component (triangles sharing a vertex are connected),
/// and the triangle count of each component. `O(t α(t))`.
pub fn triangle_components(mesh: &TriMesh) -> (Vec<u32>, Vec<usize>) {
    let mut uf = UnionFind::new(mesh.vertices.len());
    for t in &mesh.triangles {
        uf.union(t[0], t[1]);
        uf.union(t[1], t[2]);
    }
    let mut id = vec![u32::MAX; mesh.vertices.len()];
    let mut sizes = Vec::new();
    let labels = mesh
        .triangles
        .iter()
        .map(|t| {
            let root = uf.find(t[0]) as usize;
            if id[root] == u32::MAX {
                id[root] = sizes.len() as u32;
                sizes.push(0);
            }
            sizes[id[root] as usize] += 1;
            id[root]
        })
        .collect();
    (labels, sizes)
}

/// One undirected edge with its use counts in each direction.
pub(crate) struct EdgeUse {
    /// Lower vertex id.
    pub lo: u32,
    /// Higher vertex id.
    pub hi: u32,
    /// Half-edges from `lo` to `hi`.
    pub forward: u32,
    /// Half-edges from `hi` to `lo`.
    pub backward: u32,
}

/// Whether some edge of `triangles` is used by exactly one of them (the mesh has a border):
/// the border test of [`analyze`] alone, without the rest of its work.
pub fn has_boundary_edge(triangles: &[[u32; 3]]) -> bool {
    collect_edges(triangles)
        .iter()
        .any(|e| e.forward + e.backward == 1)
}

/// The half-edges of `triangles` bucketed by their lower vertex (a counting sort, `O(F)`): vertex
/// `v`'s are `of(v)`, each `pack(higher vertex, triangle, lower → higher
/// is the triangle's direction)`, sorted within the bucket (a vertex has few).
fn by_lower_vertex(
    triangles: &[[u32; 3]],
    pack: impl Fn(u32, usize, bool) -> u64,
) -> ByVertex<u64> {
    let n = (triangles.iter().flatten()).fold(0, |m, &v| m.max(v as usize + 1));
    let mut by = ByVertex::build(n, triangles.len(), |ti, k| {
        let t = &triangles[ti];
        let (a, b) = (t[k], t[(k + 1) % 3]);
        Some((a.min(b), pack(a.max(b), ti, a <= b)))
    });
    for v in 0..n {
        by.of_mut(v).sort_unstable();
    }
    by
}

/// Groups the half-edges of all triangles by undirected edge, sorted by `(lo, hi)`
/// ([`by_lower_vertex`]; a comparison sort of all half-edges was a tenth of the simplification's
/// time).
pub(crate) fn collect_edges(triangles: &[[u32; 3]]) -> Vec<EdgeUse> {
    // The higher vertex and the direction of each half-edge, packed `hi << 1 | forward`.
    let upper = by_lower_vertex(triangles, |hi, _, forward| {
        (u64::from(hi) << 1) | forward as u64
    });
    let mut edges: Vec<EdgeUse> = Vec::with_capacity(upper.len() / 2 + 1);
    for lo in 0..upper.vertices() {
        for &x in upper.of(lo) {
            let (hi, forward) = ((x >> 1) as u32, x & 1 == 1);
            match edges.last_mut() {
                Some(e) if e.lo == lo as u32 && e.hi == hi => {
                    if forward {
                        e.forward += 1
                    } else {
                        e.backward += 1
                    }
                }
                _ => edges.push(EdgeUse {
                    lo: lo as u32,
                    hi,
                    forward: forward as u32,
                    backward: (!forward) as u32,
                }),
            }
        }
    }
    edges
}

/// Every half-edge as `(lo << 32 | hi, triangle)` (the undirected edge's key and the triangle
/// using it), sorted: the order of a comparison sort of those pairs ([`by_lower_vertex`]).
pub(crate) fn sorted_half_edges(triangles: &[[u32; 3]]) -> Vec<(u64, u32)> {
    // The higher vertex and the triangle of each half-edge, packed `hi << 32 | triangle`.
    let upper = by_lower_vertex(triangles, |hi, ti, _| (u64::from(hi) << 32) | ti as u64);
    let mut half = Vec::with_capacity(upper.len());
    for lo in 0..upper.vertices() {
        half.extend((upper.of(lo).iter()).map(|&x| (((lo as u64) << 32) | (x >> 32), x as u32)));
    }
    half
}

/// Number of vertices whose incident triangles do not form a single edge-connected fan.
fn count_non_manifold_vertices(triangles: &[[u32; 3]], n: usize) -> usize {
    let incident = vertex_triangles(n, triangles, |_| false);
    // Vertices in parallel, each thread with its own scratch (the fans are independent).
    let scratch = || (Vec::<(u32, u32)>::new(), UnionFind::new(0));
    (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .map_init(scratch, |(spokes, uf), v| {
            let fan = incident.of(v);
            if fan.len() <= 1 {
                return 0;
            }
            spokes.clear();
            for (local, &ti) in fan.iter().enumerate() {
                for &w in &triangles[ti as usize] {
                    if w as usize != v {
                        spokes.push((w, local as u32));
                    }
                }
            }
            spokes.sort_unstable();
            uf.reset(fan.len());
            for pair in spokes.windows(2) {
                if pair[0].0 == pair[1].0 {
                    uf.union(pair[0].1, pair[1].1);
                }
            }
            let root = uf.find(0);
            usize::from((1..fan.len() as u32).any(|i| uf.find(i) != root))
        })
        .sum()
}

/// Computes the topological summary of `mesh` (indices only; positions and normals are not read).
///
/// # Example
/// ```
/// use rbfsurf::geometry::TriMesh;
/// let tet = TriMesh {
///     vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
///     normals: vec![],
///     triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
///     colors: vec![],
/// };
/// let t = rbfsurf::mesh::analyze(&tet);
/// assert!(t.watertight && t.manifold && t.oriented);
/// assert_eq!((t.euler, t.genus, t.components), (2, Some(0), 1));
/// ```
pub fn analyze(mesh: &TriMesh) -> MeshTopology {
    let tris = &mesh.triangles;
    let n = tris
        .iter()
        .flat_map(|t| t.iter())
        .map(|&v| v as usize + 1)
        .max()
        .unwrap_or(0);
    let mut used = vec![false; n];
    let mut uf = UnionFind::new(n);
    let mut degenerate = 0;
    for t in tris {
        for &v in t {
            used[v as usize] = true;
        }
        uf.union(t[0], t[1]);
        uf.union(t[0], t[2]);
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            degenerate += 1;
        }
    }
    let edges = collect_edges(tris);
    let mut boundary_uf = UnionFind::new(n);
    let mut on_boundary = vec![false; n];
    let (mut boundary_edges, mut non_manifold_edges, mut oriented) = (0, 0, true);
    for e in &edges {
        let uses = e.forward + e.backward;
        if uses == 1 {
            boundary_edges += 1;
            boundary_uf.union(e.lo, e.hi);
            on_boundary[e.lo as usize] = true;
            on_boundary[e.hi as usize] = true;
        } else if uses > 2 {
            non_manifold_edges += 1;
        }
        if e.forward > 1 || e.backward > 1 {
            oriented = false;
        }
    }
    let boundary_loops = (0..n as u32)
        .filter(|&v| on_boundary[v as usize] && boundary_uf.find(v) == v)
        .count();
    let non_manifold_vertices = count_non_manifold_vertices(tris, n);
    let vertices = used.iter().filter(|&&u| u).count();
    let watertight = !tris.is_empty() && boundary_edges == 0 && non_manifold_edges == 0;
    let manifold = non_manifold_edges == 0 && non_manifold_vertices == 0 && degenerate == 0;
    let euler = vertices as i64 - edges.len() as i64 + tris.len() as i64;
    let components = (0..n as u32)
        .filter(|&v| used[v as usize] && uf.find(v) == v)
        .count();
    let genus = (watertight && manifold && oriented)
        .then(|| total_genus(tris, &edges, &used, &mut uf))
        .flatten();
    MeshTopology {
        vertices,
        triangles: tris.len(),
        edges: edges.len(),
        components,
        watertight,
        manifold,
        oriented,
        boundary_edges,
        boundary_loops,
        non_manifold_edges,
        non_manifold_vertices,
        degenerate_triangles: degenerate,
        euler,
        genus,
    }
}

/// `Σ_c (2 − χ_c) / 2` over the vertex-connected components, or `None` when some `χ_c` is odd.
fn total_genus(
    tris: &[[u32; 3]],
    edges: &[EdgeUse],
    used: &[bool],
    uf: &mut UnionFind,
) -> Option<i64> {
    let n = used.len();
    let mut chi = vec![0i64; n];
    for v in 0..n as u32 {
        if used[v as usize] {
            chi[uf.find(v) as usize] += 1;
        }
    }
    for e in edges {
        chi[uf.find(e.lo) as usize] -= 1;
    }
    for t in tris {
        chi[uf.find(t[0]) as usize] += 1;
    }
    let mut genus = 0;
    for v in 0..n as u32 {
        if used[v as usize] && uf.find(v) == v {
            let c = chi[v as usize];
            if (2 - c) % 2 != 0 {
                return None;
            }
            genus += (2 - c) / 2;
        }
    }
    Some(genus)
}

/// The three corner positions of triangle `t`, or `None` when an index is out of range.
fn corners(mesh: &TriMesh, t: &[u32; 3]) -> Option<[Point3; 3]> {
    Some([
        *mesh.vertices.get(t[0] as usize)?,
        *mesh.vertices.get(t[1] as usize)?,
        *mesh.vertices.get(t[2] as usize)?,
    ])
}

/// Signed enclosed volume `Σ a · (b × c) / 6` (cubic mesh units); positive for a closed mesh wound
/// counter-clockwise seen from outside. Triangles with out-of-range indices are skipped.
pub fn signed_volume(mesh: &TriMesh) -> f64 {
    mesh.triangles
        .iter()
        .filter_map(|t| corners(mesh, t))
        .map(|[a, b, c]| dot(a, cross(b, c)))
        .sum::<f64>()
        / 6.0
}

/// Total surface area `Σ |(b − a) × (c − a)| / 2` (squared mesh units). Triangles with out-of-range
/// indices are skipped.
pub fn area(mesh: &TriMesh) -> f64 {
    use crate::geometry::sub;
    mesh.triangles
        .iter()
        .filter_map(|t| corners(mesh, t))
        .map(|[a, b, c]| 0.5 * norm(cross(sub(b, a), sub(c, a))))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::{cube, merge, tetrahedron, torus};

    #[test]
    fn tetrahedron_and_cube_are_spheres() {
        for (mesh, volume) in [(tetrahedron(), 1.0 / 6.0), (cube([0.0; 3], 2.0), 8.0)] {
            let t = analyze(&mesh);
            assert!(t.watertight && t.manifold && t.oriented, "{t:?}");
            assert_eq!((t.euler, t.genus, t.components), (2, Some(0), 1));
            assert_eq!((t.boundary_edges, t.boundary_loops), (0, 0));
            assert!((signed_volume(&mesh) - volume).abs() < 1e-12);
        }
        assert!((area(&cube([1.0; 3], 2.0)) - 24.0).abs() < 1e-12);
        assert!((area(&tetrahedron()) - (1.5 + 3f64.sqrt() / 2.0)).abs() < 1e-12);
    }

    #[test]
    fn the_border_test_agrees_with_analyze() {
        let closed = merge(&torus(2.0, 0.5, 24, 12), &cube([5.0; 3], 1.0));
        assert!(!has_boundary_edge(&closed.triangles));
        for drop in [0, 7, closed.triangles.len() - 1] {
            let mut open = closed.clone();
            open.triangles.remove(drop);
            assert_eq!(analyze(&open).boundary_edges, 3);
            assert!(has_boundary_edge(&open.triangles));
        }
        // An edge used three times is not a border.
        let mut three = tetrahedron();
        let t = three.triangles[0];
        three.triangles.push([t[0], t[1], 3 + t[2]]);
        three.vertices.extend(three.vertices.clone());
        let a = analyze(&three);
        assert_eq!(has_boundary_edge(&three.triangles), a.boundary_edges > 0);
        assert!(!has_boundary_edge(&[]));
    }

    #[test]
    fn torus_has_genus_one() {
        let mesh = torus(2.0, 0.5, 48, 24);
        let t = analyze(&mesh);
        assert!(t.watertight && t.manifold && t.oriented, "{t:?}");
        assert_eq!((t.vertices, t.triangles, t.edges), (1152, 2304, 3456));
        assert_eq!((t.euler, t.genus, t.components), (0, Some(1), 1));
        let v = signed_volume(&mesh);
        let exact = 2.0 * std::f64::consts::PI.powi(2) * 2.0 * 0.25;
        assert!(
            v > 0.0 && (v - exact).abs() < 0.03 * exact,
            "{v} vs {exact}"
        );
    }

    #[test]
    fn two_cubes_are_two_components() {
        let mesh = merge(&cube([0.0; 3], 1.0), &cube([3.0, 0.0, 0.0], 1.0));
        let t = analyze(&mesh);
        assert_eq!((t.components, t.euler, t.genus), (2, 4, Some(0)));
        assert!(t.watertight && t.manifold && t.oriented);
    }

    #[test]
    fn open_cube_has_one_boundary_loop() {
        let mut mesh = cube([0.0; 3], 1.0);
        mesh.triangles.truncate(10);
        let t = analyze(&mesh);
        assert!(!t.watertight && t.manifold && t.oriented);
        assert_eq!(
            (t.boundary_edges, t.boundary_loops, t.euler, t.genus),
            (4, 1, 1, None)
        );
    }

    #[test]
    fn flipped_triangle_breaks_orientation() {
        let mut mesh = cube([0.0; 3], 1.0);
        mesh.triangles[3].swap(1, 2);
        let t = analyze(&mesh);
        assert!(t.watertight && t.manifold && !t.oriented);
        assert_eq!((t.euler, t.genus), (2, None));
    }

    #[test]
    fn bow_tie_vertex_is_not_manifold() {
        // Two tetrahedra sharing only vertex 0 (the second is the first mirrored through the origin).
        let a = tetrahedron();
        let mut b = a.clone();
        for p in &mut b.vertices {
            *p = [-p[0], -p[1], -p[2]];
        }
        let mut mesh = merge(&a, &b);
        for t in mesh.triangles.iter_mut().skip(4) {
            for v in t.iter_mut() {
                if *v == 4 {
                    *v = 0;
                }
            }
        }
        let t = analyze(&mesh);
        assert!(t.watertight && t.oriented && !t.manifold, "{t:?}");
        assert_eq!(
            (t.non_manifold_vertices, t.non_manifold_edges, t.components),
            (1, 0, 1)
        );
        assert_eq!(t.genus, None);
        // Two triangles meeting in one vertex: open and not vertex-manifold.
        let fan = TriMesh {
            vertices: vec![[0.0; 3]; 5],
            normals: vec![],
            triangles: vec![[0, 1, 2], [0, 3, 4]],
            colors: Vec::new(),
        };
        let t = analyze(&fan);
        assert_eq!(
            (t.non_manifold_vertices, t.boundary_loops, t.boundary_edges),
            (1, 1, 6)
        );
    }

    #[test]
    fn three_triangles_on_one_edge_are_non_manifold() {
        let mesh = TriMesh {
            vertices: vec![[0.0; 3]; 5],
            normals: vec![],
            triangles: vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
            colors: Vec::new(),
        };
        let t = analyze(&mesh);
        assert_eq!(t.non_manifold_edges, 1);
        assert!(!t.manifold && !t.oriented && !t.watertight);
    }

    #[test]
    fn empty_mesh_is_not_watertight() {
        let t = analyze(&TriMesh::default());
        assert_eq!(
            (t.vertices, t.triangles, t.components, t.euler),
            (0, 0, 0, 0)
        );
        assert!(!t.watertight);
        assert_eq!(t.genus, None);
        let json = serde_json::to_value(&t).unwrap();
        for key in [
            "vertices",
            "triangles",
            "components",
            "watertight",
            "manifold",
            "euler",
            "genus",
        ] {
            assert!(json.get(key).is_some(), "{key}");
        }
    }

    #[test]
    fn half_edges_come_sorted_like_a_comparison_sort() {
        let mut odd = cube([0.0; 3], 1.0);
        odd.triangles.push(odd.triangles[3]);
        odd.triangles.swap(0, 7);
        let fan = [[0u32, 1, 2], [0, 1, 3], [1, 0, 4], [7, 8, 9], [9, 8, 7]];
        for triangles in [
            torus(1.0, 0.3, 24, 12).triangles,
            odd.triangles,
            fan.to_vec(),
            Vec::new(),
        ] {
            let mut want: Vec<(u64, u32)> = Vec::new();
            for (ti, t) in triangles.iter().enumerate() {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    want.push(((u64::from(a.min(b)) << 32) | u64::from(a.max(b)), ti as u32));
                }
            }
            want.sort_unstable();
            assert_eq!(sorted_half_edges(&triangles), want);
        }
    }

    #[test]
    fn edges_are_grouped_like_a_brute_force_count() {
        // A torus, a cube with a triangle repeated, one flipped and one removed, and a fan with
        // an edge used three times: every edge and its direction counts as a map counts them.
        let mut odd = cube([0.0; 3], 1.0);
        odd.triangles.push(odd.triangles[3]);
        odd.triangles[5] = [
            odd.triangles[5][0],
            odd.triangles[5][2],
            odd.triangles[5][1],
        ];
        odd.triangles.remove(0);
        let fan = [[0u32, 1, 2], [0, 1, 3], [1, 0, 4], [7, 8, 9]];
        for triangles in [
            torus(1.0, 0.3, 24, 12).triangles,
            odd.triangles,
            fan.to_vec(),
        ] {
            let mut count = std::collections::BTreeMap::<(u32, u32), (u32, u32)>::new();
            for t in &triangles {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    let c = count.entry((a.min(b), a.max(b))).or_default();
                    if a <= b { c.0 += 1 } else { c.1 += 1 }
                }
            }
            let edges = collect_edges(&triangles);
            let got: Vec<((u32, u32), (u32, u32))> = (edges.iter())
                .map(|e| ((e.lo, e.hi), (e.forward, e.backward)))
                .collect();
            assert_eq!(got, count.into_iter().collect::<Vec<_>>());
        }
    }
}
