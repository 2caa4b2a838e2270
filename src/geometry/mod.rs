//! Vocabulary types shared by every stage: points, boxes, triangle meshes.
//!
//! Coordinates are `f64` triples. Inside the pipeline everything is in *normalised units*
//! (the input's bounding box mapped into the unit cube, see [`crate::geometry::Normalization`]);
//! meshes are mapped back to input units on output.

mod aabb;
mod normalize;
pub mod pca;
pub mod synthetic;

pub use aabb::Aabb;
pub use normalize::Normalization;

/// A point or vector in 3D (x, y, z).
pub type Point3 = [f64; 3];

/// A point set as read from a file: positions and, optionally, one normal per point.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// Positions, in the units of the source.
    pub points: Vec<Point3>,
    /// Per-point normals (same length as `points`), not necessarily unit length, when the source had them.
    pub normals: Option<Vec<Point3>>,
}

/// An indexed triangle mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<Point3>,
    /// Unit vertex normals (outward), same length as `vertices`, or empty when unknown.
    pub normals: Vec<Point3>,
    /// Triangles as vertex indices, counter-clockwise seen from outside (right-hand rule gives the outward normal).
    pub triangles: Vec<[u32; 3]>,
}

/// `a − b`.
#[inline]
pub fn sub(a: Point3, b: Point3) -> Point3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
#[inline]
pub fn add(a: Point3, b: Point3) -> Point3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s · a`.
#[inline]
pub fn scale(a: Point3, s: f64) -> Point3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Dot product.
#[inline]
pub fn dot(a: Point3, b: Point3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product `a × b`.
#[inline]
pub fn cross(a: Point3, b: Point3) -> Point3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Squared Euclidean norm.
#[inline]
pub fn norm2(a: Point3) -> f64 {
    dot(a, a)
}

/// Euclidean norm.
#[inline]
pub fn norm(a: Point3) -> f64 {
    norm2(a).sqrt()
}

/// Squared distance between two points.
#[inline]
pub fn dist2(a: Point3, b: Point3) -> f64 {
    norm2(sub(a, b))
}

/// `a / |a|`, or `None` when `|a|` is zero or not finite.
#[inline]
pub fn normalized(a: Point3) -> Option<Point3> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}
