//! Vocabulary types shared by every stage: points, boxes, triangle meshes.
//!
//! Coordinates are `f64` triples. Inside the pipeline everything is in *normalised units*
//! (the input's bounding box mapped into the unit cube, see [`crate::geometry::Normalization`]);
//! meshes are mapped back to input units on output.

mod aabb;
mod normalize;
pub(crate) mod pca;
mod surround;
#[cfg(test)]
pub(crate) use surround::fibonacci_direction;
pub mod synthetic;

pub use aabb::Aabb;
pub use normalize::Normalization;
pub use surround::{largest_empty_cone, surround_cone};

/// A point or vector in 3D (x, y, z).
pub type Point3 = [f64; 3];

/// A point set as read from a file: positions and, optionally, one normal per point.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// Positions, in the units of the source.
    pub points: Vec<Point3>,
    /// Per-point normals (same length as `points`), not necessarily unit length, when the source had them.
    pub normals: Option<Vec<Point3>>,
    /// Per-point colour (same length as `points`): red, green, blue in [0, 1] as the source stores
    /// them (sRGB-encoded, the scanners' convention; 8- and 16-bit sources both scaled to [0, 1]).
    pub colors: Option<Vec<[f32; 3]>>,
    /// Per-point return intensity (same length as `points`) in [0, 1] (see docs/formats.md for
    /// each format's scaling).
    pub intensity: Option<Vec<f32>>,
    /// Coordinate reference system the source declares, verbatim: OGC WKT, `EPSG:<code>` from
    /// GeoTIFF keys, or an E57 `coordinateMetadata` string. Never interpreted, only passed on.
    pub crs: Option<String>,
}

impl PointCloud {
    /// The cloud restricted to the points at `keep` (in that order), with every per-point
    /// attribute (normals, colours, intensity) selected alike and the CRS kept.
    /// Panics if an index is out of range.
    pub fn select(&self, keep: &[usize]) -> PointCloud {
        let (colors, intensity) = self.attributes_at(keep);
        PointCloud {
            points: keep.iter().map(|&i| self.points[i]).collect(),
            normals: (self.normals.as_ref()).map(|v| keep.iter().map(|&i| v[i]).collect()),
            colors,
            intensity,
            crs: self.crs.clone(),
        }
    }

    /// Colours and intensity of the points at `keep`; an attribute whose length differs from the
    /// point count is dropped (`None`). Panics if an index is out of range.
    pub fn attributes_at(&self, keep: &[usize]) -> (Option<Vec<[f32; 3]>>, Option<Vec<f32>>) {
        let n = self.points.len();
        let colors = (self.colors.as_ref())
            .filter(|v| v.len() == n)
            .map(|v| keep.iter().map(|&i| v[i]).collect());
        let intensity = (self.intensity.as_ref())
            .filter(|v| v.len() == n)
            .map(|v| keep.iter().map(|&i| v[i]).collect());
        (colors, intensity)
    }
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
    /// Per-vertex colour (same length as `vertices`), red, green, blue in [0, 1] in the input's
    /// encoding (sRGB for scanner RGB), or empty when the mesh has none.
    pub colors: Vec<[f32; 3]>,
}

// Vector helpers, generic over the dimension (3D here, 2D in the curve workbench); by value,
// arrays being `Copy`. Sums run in index order from 0, so 3D results are bit-identical to the
// written-out `a[0] * b[0] + a[1] * b[1] + a[2] * b[2]`.

/// `a − b`.
#[inline]
pub fn sub<const D: usize>(a: [f64; D], b: [f64; D]) -> [f64; D] {
    std::array::from_fn(|k| a[k] - b[k])
}

/// `a + b`.
#[inline]
pub fn add<const D: usize>(a: [f64; D], b: [f64; D]) -> [f64; D] {
    std::array::from_fn(|k| a[k] + b[k])
}

/// `s · a`.
#[inline]
pub fn scale<const D: usize>(a: [f64; D], s: f64) -> [f64; D] {
    a.map(|v| v * s)
}

/// Dot product.
#[inline]
pub fn dot<const D: usize>(a: [f64; D], b: [f64; D]) -> f64 {
    let mut s = a[0] * b[0];
    for k in 1..D {
        s += a[k] * b[k];
    }
    s
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
pub fn norm2<const D: usize>(a: [f64; D]) -> f64 {
    dot(a, a)
}

/// Euclidean norm.
#[inline]
pub fn norm<const D: usize>(a: [f64; D]) -> f64 {
    norm2(a).sqrt()
}

/// Squared distance between two points.
#[inline]
pub fn dist2<const D: usize>(a: [f64; D], b: [f64; D]) -> f64 {
    norm2(sub(a, b))
}

/// `a / |a|`, or `None` when `|a|` is zero or not finite.
#[inline]
pub fn normalized<const D: usize>(a: [f64; D]) -> Option<[f64; D]> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

/// The median of `v` (the upper middle for an even length; `v` is reordered); 0 when empty.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}
