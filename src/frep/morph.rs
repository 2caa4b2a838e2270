//! Metamorphosis between two solids (the seed's Fig. 4; Pasko et al. 1995 / Savchenko et al.):
//! `F_t(x) = (1 − t) F_A(x) + t F_B(T x)`, `t = 0 … 1`, where the space mapping `T` first aligns B to
//! A (bounding box, principal axes or a user affine map), so that the solids overlap and the
//! topology changes in between (a sphere-like scan becomes a torus through a frame where the hole
//! opens). With an obstacle `O`, every frame is `F_t ∩ ¬O` (R-difference), so no frame enters it.
//! Frames are meshed with [`super::mesh::mesh_solid`] on the union of both boxes (the same grid for
//! every frame) and reported with their topology.

use super::FrepError;
use super::mesh::{CsgParams, mesh_solid};
use super::ops::{Affine, Solid};
use crate::geometry::pca::pca;
use crate::geometry::{Aabb, Point3, TriMesh, cross, dot};
use crate::progress::Progress;
use serde::Serialize;
use std::sync::Arc;

/// How B is aligned to A before the morph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Align {
    /// B's bounding box onto A's, axis by axis (the default).
    BoundingBox,
    /// B's principal axes and spreads onto A's (field operands: their data points; primitives:
    /// falls back to the bounding box).
    Pca,
    /// No alignment (both as they are).
    None,
    /// A user map from A's space to B's: `x_B = M x_A + t`, rows `[m00 m01 m02 t0]`, …
    Affine([[f64; 4]; 3]),
}

impl Align {
    /// Report name.
    pub fn name(&self) -> &'static str {
        match self {
            Align::BoundingBox => "bbox",
            Align::Pca => "pca",
            Align::None => "none",
            Align::Affine(_) => "affine",
        }
    }
}

/// Parameters of a morph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MorphParams {
    /// Frames, including both ends (2..=256).
    pub frames: usize,
    /// Meshing resolution of every frame.
    pub mesh: CsgParams,
    /// How to align B to A.
    pub align: Align,
}

/// One frame's numbers.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FrameReport {
    /// Morph parameter, 0 = A, 1 = B aligned.
    pub t: f64,
    /// Connected components.
    pub components: usize,
    /// Every edge shared by exactly two triangles.
    pub watertight: bool,
    /// Edge- and vertex-manifold.
    pub manifold: bool,
    /// Genus when watertight and manifold.
    pub genus: Option<i64>,
    /// Triangles.
    pub triangles: usize,
    /// Enclosed volume, input units cubed.
    pub volume: f64,
}

/// The `report.json` of `rbfsurf morph`.
#[derive(Debug, Clone, Serialize)]
pub struct MorphReport {
    /// Alignment used.
    pub align: &'static str,
    /// The map `x_B = M x_A + t` actually used, rows `[M | t]`.
    pub map: [[f64; 4]; 3],
    /// Whether an obstacle was subtracted.
    pub obstacle: bool,
    /// Grid cells along the longest edge.
    pub resolution: usize,
    /// Every frame.
    pub frames: Vec<FrameReport>,
    /// Seconds for all frames.
    pub seconds: f64,
}

/// The map `x ↦ M x + t` from A's space to B's.
fn alignment(a: &Solid, b: &Solid, align: Align) -> Result<([[f64; 3]; 3], Point3), FrepError> {
    let empty = || FrepError::Empty("an operand of the morph is empty".into());
    let (ba, bb) = (a.bounds().ok_or_else(empty)?, b.bounds().ok_or_else(empty)?);
    let bbox = || {
        let (ea, eb, ca, cb) = (ba.extent(), bb.extent(), ba.center(), bb.center());
        let s = [0, 1, 2].map(|k| if ea[k] > 0.0 { eb[k] / ea[k] } else { 1.0 });
        let m = [[s[0], 0.0, 0.0], [0.0, s[1], 0.0], [0.0, 0.0, s[2]]];
        (m, [0, 1, 2].map(|k| cb[k] - s[k] * ca[k]))
    };
    Ok(match align {
        Align::None => (
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [0.0; 3],
        ),
        Align::BoundingBox => bbox(),
        Align::Affine(r) => (
            [0, 1, 2].map(|i| [r[i][0], r[i][1], r[i][2]]),
            [r[0][3], r[1][3], r[2][3]],
        ),
        Align::Pca => match (data_points(a), data_points(b)) {
            (Some(pa), Some(pb)) => pca_map(&pa, &pb),
            _ => bbox(),
        },
    })
}

fn data_points(s: &Solid) -> Option<Vec<Point3>> {
    match s {
        Solid::Field(m) => Some(
            m.points
                .iter()
                .map(|p| m.normalization.inverse(p))
                .collect(),
        ),
        _ => None,
    }
}

/// Principal frame with axes signed by the third moment (so mirrored shapes line up) and made
/// right-handed.
fn frame(points: &[Point3]) -> (Point3, [Point3; 3], [f64; 3]) {
    let p = pca(points);
    let mut axes = p.axes;
    for ax in axes.iter_mut().take(2) {
        let skew: f64 = points
            .iter()
            .map(|q| {
                dot(
                    *ax,
                    [
                        q[0] - p.centroid[0],
                        q[1] - p.centroid[1],
                        q[2] - p.centroid[2],
                    ],
                )
                .powi(3)
            })
            .sum();
        if skew < 0.0 {
            *ax = ax.map(|c| -c);
        }
    }
    axes[2] = cross(axes[0], axes[1]);
    (p.centroid, axes, p.variances.map(|v| v.max(1e-300).sqrt()))
}

fn pca_map(a: &[Point3], b: &[Point3]) -> ([[f64; 3]; 3], Point3) {
    let (ca, ra, sa) = frame(a);
    let (cb, rb, sb) = frame(b);
    // x_B = c_B + Σ_k (σ_B,k / σ_A,k) ((x − c_A)·a_k) b_k
    let mut m = [[0.0; 3]; 3];
    for k in 0..3 {
        let s = sb[k] / sa[k];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += s * rb[k][i] * ra[k][j];
            }
        }
    }
    let t = [0, 1, 2].map(|i| cb[i] - dot(m[i], ca));
    (m, t)
}

/// Morph `a` into `b` (see the module doc); `on_frame` gets every frame's mesh as it is made.
/// Returns the report.
pub fn morph(
    a: Solid,
    b: Solid,
    obstacle: Option<Solid>,
    params: &MorphParams,
    progress: &dyn Progress,
    mut on_frame: impl FnMut(usize, TriMesh) -> Result<(), FrepError>,
) -> Result<MorphReport, FrepError> {
    if !(2..=256).contains(&params.frames) {
        return Err(FrepError::Param {
            name: "frames",
            value: params.frames.to_string(),
            expected: "2..=256 frames including both ends",
        });
    }
    let start = std::time::Instant::now();
    let (m, t) = alignment(&a, &b, params.align)?;
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if !(det.abs() > 1e-300 && det.is_finite()) {
        return Err(FrepError::Param {
            name: "align",
            value: format!("{m:?}"),
            expected: "an invertible map",
        });
    }
    // Values of B are in B's units: divide by the map's mean scale to keep them distance-like.
    let aligned = Solid::Affine(
        Box::new(b),
        Affine {
            m,
            t,
            gain: 1.0 / det.abs().cbrt(),
        },
    );
    let (a, b) = (Arc::new(a), Arc::new(aligned));
    let obstacle = obstacle.map(Arc::new);
    let domain_of = |s: Solid| -> Result<Aabb, FrepError> {
        s.bounds()
            .ok_or_else(|| FrepError::Empty("the morph's operands are empty".into()))
    };
    let box_all = domain_of(Solid::Union(
        Box::new(Solid::Shared(Arc::clone(&a))),
        Box::new(Solid::Shared(Arc::clone(&b))),
        0.0,
    ))?;
    let mut frames = Vec::with_capacity(params.frames);
    for i in 0..params.frames {
        if progress.cancelled() {
            return Err(FrepError::Polygonize(
                crate::polygonize::PolygonizeError::Cancelled,
            ));
        }
        let t = i as f64 / (params.frames - 1) as f64;
        let mut solid = Solid::Morph(Arc::clone(&a), Arc::clone(&b), t, box_all);
        if let Some(o) = &obstacle {
            solid = Solid::Difference(Box::new(solid), Box::new(Solid::Shared(Arc::clone(o))), 0.0);
        }
        let (mesh, rep) = mesh_solid(&solid, "", &params.mesh, &crate::progress::NoProgress)?;
        frames.push(FrameReport {
            t,
            components: rep.mesh.components,
            watertight: rep.mesh.watertight,
            manifold: rep.mesh.manifold,
            genus: rep.mesh.genus,
            triangles: rep.mesh.triangles,
            volume: crate::mesh::topology::signed_volume(&mesh),
        });
        on_frame(i, mesh)?;
        progress.fraction((i + 1) as f64 / params.frames as f64);
    }
    Ok(MorphReport {
        align: params.align.name(),
        map: [0, 1, 2].map(|i| [m[i][0], m[i][1], m[i][2], t[i]]),
        obstacle: obstacle.is_some(),
        resolution: params.mesh.resolution,
        frames,
        seconds: start.elapsed().as_secs_f64(),
    })
}
