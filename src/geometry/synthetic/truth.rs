//! Truth meshes: parametric triangulations of the synthetic shapes, closed, manifold, wound
//! counter-clockwise seen from outside, with the analytic outward normals at the vertices.
//!
//! Sphere-like shapes use a latitude–longitude grid with one vertex per pole (`res` segments around
//! the equator, `res / 2` from pole to pole); torus and knot a periodic grid whose second direction
//! gets segments in proportion to its length (near-equilateral quads; the knot's centre line is
//! divided equally by arc length). Vertices lie on the surface; the chordal error is
//! `O(h² κ)` for edge length `h` and curvature `κ`.

use super::{Shape, bumpy, knot};
use crate::geometry::{Point3, TriMesh};
use std::f64::consts::{PI, TAU};

impl Shape {
    /// Grid dimensions `(around, across)` of [`Shape::truth_mesh`] for `resolution`.
    fn truth_grid(&self, resolution: usize) -> (usize, usize) {
        let res = resolution.max(8);
        let across = |ratio: f64| ((res as f64 * ratio).round() as usize).max(3);
        match *self {
            Shape::Sphere { .. } | Shape::TwoSpheres { .. } | Shape::BumpySphere { .. } => {
                (res, (res / 2).max(2))
            }
            Shape::Torus { major, minor, .. } => (res, across(minor / (major + minor))),
            Shape::Knot { scale, tube, .. } => {
                (res, across(TAU * tube / (scale * knot::curve_length())))
            }
        }
    }

    /// Number of triangles [`Shape::truth_mesh`] gives for `resolution`.
    pub fn truth_triangles(&self, resolution: usize) -> usize {
        let (a, b) = self.truth_grid(resolution);
        let per = match self {
            Shape::Torus { .. } | Shape::Knot { .. } => 2 * a * b,
            _ => 2 * a * (b - 1),
        };
        per * self.components()
    }

    /// A closed, manifold, outward-oriented triangulation of the surface (vertices on it, analytic
    /// unit normals), with `resolution` (≥ 8) segments around the longest parameter circle: the
    /// equator for sphere-like shapes, the outer equator for the torus, the centre line for the knot.
    /// Triangle count: [`Shape::truth_triangles`] (≈ `resolution²` for spheres, less for thin tubes).
    pub fn truth_mesh(&self, resolution: usize) -> TriMesh {
        let (a, b) = self.truth_grid(resolution);
        match *self {
            Shape::Sphere { center, radius } => {
                lat_long(a, b, |u| (add_scaled(center, u, radius), u))
            }
            Shape::TwoSpheres {
                center,
                radius,
                gap,
            } => {
                let off = radius + 0.5 * gap;
                let mut mesh = TriMesh::default();
                for sign in [-1.0, 1.0] {
                    let c = [center[0] + sign * off, center[1], center[2]];
                    append(&mut mesh, lat_long(a, b, |u| (add_scaled(c, u, radius), u)));
                }
                mesh
            }
            Shape::BumpySphere {
                center,
                radius,
                amplitude,
            } => lat_long(a, b, |u| bumpy::surface_point(u, center, radius, amplitude)),
            Shape::Torus {
                center,
                major,
                minor,
            } => periodic_grid(a, b, |i, j| {
                let (u, v) = (TAU * i as f64 / a as f64, TAU * j as f64 / b as f64);
                let n = [v.cos() * u.cos(), v.cos() * u.sin(), v.sin()];
                let r = major + minor * v.cos();
                let p = [
                    center[0] + r * u.cos(),
                    center[1] + r * u.sin(),
                    center[2] + minor * v.sin(),
                ];
                (p, n)
            }),
            Shape::Knot {
                center,
                scale,
                tube,
            } => {
                // X_t × X_v points inwards, so the grid runs (v, t).
                let ts = knot::arc_length_parameters(a);
                periodic_grid(b, a, |j, i| {
                    knot::surface_point(center, scale, tube, ts[i], TAU * j as f64 / b as f64)
                })
            }
        }
    }
}

fn add_scaled(c: Point3, u: Point3, s: f64) -> Point3 {
    [c[0] + s * u[0], c[1] + s * u[1], c[2] + s * u[2]]
}

/// Appends `other` to `mesh`, renumbering its vertices.
fn append(mesh: &mut TriMesh, other: TriMesh) {
    let base = mesh.vertices.len() as u32;
    mesh.vertices.extend(other.vertices);
    mesh.normals.extend(other.normals);
    mesh.triangles
        .extend(other.triangles.iter().map(|t| t.map(|v| v + base)));
}

/// Latitude–longitude grid of a star-shaped surface given by `f(unit direction) → (point, normal)`:
/// `lon` segments around, `lat ≥ 2` from the north pole (z = +1) to the south pole.
fn lat_long(lon: usize, lat: usize, f: impl Fn(Point3) -> (Point3, Point3)) -> TriMesh {
    let mut mesh = TriMesh::default();
    let push = |u: Point3, mesh: &mut TriMesh| {
        let (p, n) = f(u);
        mesh.vertices.push(p);
        mesh.normals.push(n);
    };
    push([0.0, 0.0, 1.0], &mut mesh);
    for i in 1..lat {
        let theta = PI * i as f64 / lat as f64;
        for j in 0..lon {
            let phi = TAU * j as f64 / lon as f64;
            let s = theta.sin();
            push([s * phi.cos(), s * phi.sin(), theta.cos()], &mut mesh);
        }
    }
    push([0.0, 0.0, -1.0], &mut mesh);
    let south = (mesh.vertices.len() - 1) as u32;
    let ring = |i: usize, j: usize| (1 + (i - 1) * lon + j % lon) as u32;
    // (θ, φ) increasing is outward (∂θ × ∂φ points away from the centre).
    for j in 0..lon {
        mesh.triangles.push([0, ring(1, j), ring(1, j + 1)]);
        mesh.triangles
            .push([ring(lat - 1, j), south, ring(lat - 1, j + 1)]);
    }
    for i in 1..lat - 1 {
        for j in 0..lon {
            let (p, q, r, s) = (
                ring(i, j),
                ring(i + 1, j),
                ring(i + 1, j + 1),
                ring(i, j + 1),
            );
            mesh.triangles.push([p, q, r]);
            mesh.triangles.push([p, r, s]);
        }
    }
    mesh
}

/// Doubly periodic `na × nb` grid; `f(i, j) → (point, normal)` with the `i` direction crossed with the
/// `j` direction pointing outwards.
fn periodic_grid(na: usize, nb: usize, f: impl Fn(usize, usize) -> (Point3, Point3)) -> TriMesh {
    let mut mesh = TriMesh::default();
    for i in 0..na {
        for j in 0..nb {
            let (p, n) = f(i, j);
            mesh.vertices.push(p);
            mesh.normals.push(n);
        }
    }
    let id = |i: usize, j: usize| ((i % na) * nb + j % nb) as u32;
    for i in 0..na {
        for j in 0..nb {
            let (p, q, r, s) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            mesh.triangles.push([p, q, r]);
            mesh.triangles.push([p, r, s]);
        }
    }
    mesh
}

#[cfg(test)]
#[path = "truth_tests.rs"]
mod tests;
