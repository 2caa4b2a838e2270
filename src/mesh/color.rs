//! Vertex colours from coloured points: each mesh vertex gets the Wendland-weighted mean of the
//! colours of the points within radius `R` of it, `w(d) = (1 − d/R)⁴ (4 d/R + 1)` — smooth (C²)
//! in the vertex position and compactly supported, the same kernel shape as the default CSRBF, so
//! the colour field is as smooth as the surface and a single noisy point cannot flip a vertex's
//! colour. A vertex with no point within `R` (surface bridged over a hole) takes the
//! inverse-square-distance mean of its [`FALLBACK_NEIGHBOURS`] nearest points. `O(V · k log N)`
//! for `k` points per ball, parallel over the vertices.

use rayon::prelude::*;

use crate::geometry::{Point3, dist2};
use crate::spatial::{IndexKind, SpatialError, build_index};

/// Points blended for a vertex that has none within the radius.
pub const FALLBACK_NEIGHBOURS: usize = 8;

/// Which point attribute colours the mesh (`--color`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColorMode {
    /// The points' RGB when the input has it (default); no colour otherwise.
    #[default]
    Rgb,
    /// The points' intensity as grey, when the input has it.
    Intensity,
    /// No vertex colours.
    None,
}

impl ColorMode {
    /// Command-line / report name.
    pub fn name(self) -> &'static str {
        match self {
            ColorMode::Rgb => "rgb",
            ColorMode::Intensity => "intensity",
            ColorMode::None => "none",
        }
    }
}

impl std::str::FromStr for ColorMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [ColorMode::Rgb, ColorMode::Intensity, ColorMode::None]
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown color '{s}' (use rgb, intensity or none)"))
    }
}

impl std::fmt::Display for ColorMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Wendland C² weight of a point at squared distance `d2` for radius `r` (0 outside).
fn weight(d2: f64, r: f64) -> f64 {
    let t = d2.sqrt() / r;
    if t >= 1.0 {
        return 0.0;
    }
    let u = 1.0 - t;
    u * u * u * u * (4.0 * t + 1.0)
}

/// Colour of every vertex from `points` (same frame) and their `values` (RGB in [0, 1]), blended
/// within `radius` (see the module documentation). `points` and `values` have equal lengths;
/// the result has one colour per vertex, each in [0, 1].
pub fn vertex_colors(
    vertices: &[Point3],
    points: &[Point3],
    values: &[[f32; 3]],
    radius: f64,
) -> Result<Vec<[f32; 3]>, SpatialError> {
    debug_assert_eq!(points.len(), values.len());
    if points.is_empty() {
        return Ok(vec![[0.5; 3]; vertices.len()]);
    }
    let index = build_index(points, IndexKind::KdTree, 16)?;
    let r = radius.max(f64::MIN_POSITIVE);
    let blend = |ids: &mut dyn Iterator<Item = (usize, f64)>| {
        let mut sum = [0.0f64; 3];
        let mut total = 0.0;
        for (i, w) in ids {
            for (s, &c) in sum.iter_mut().zip(&values[i]) {
                *s += w * f64::from(c);
            }
            total += w;
        }
        (total > 0.0).then(|| sum.map(|s| ((s / total) as f32).clamp(0.0, 1.0)))
    };
    Ok(vertices
        .par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(within, nearest), v| {
                index.within(v, r, within);
                let mut ball = within.iter().map(|&i| {
                    let i = i as usize;
                    (i, weight(dist2(*v, points[i]), r))
                });
                blend(&mut ball).unwrap_or_else(|| {
                    index.nearest_k(v, FALLBACK_NEIGHBOURS, nearest);
                    let mut near = nearest
                        .iter()
                        .map(|&(i, d)| (i as usize, 1.0 / (d * d).max(1e-300)));
                    blend(&mut near).unwrap_or([0.5; 3])
                })
            },
        )
        .collect())
}

/// Per-point colour values for `mode` from a cloud's attributes: RGB as is, intensity as grey;
/// `None` when the mode is `none` or the cloud lacks the attribute.
pub fn point_values(
    mode: ColorMode,
    colors: Option<&[[f32; 3]]>,
    intensity: Option<&[f32]>,
) -> Option<Vec<[f32; 3]>> {
    match mode {
        ColorMode::Rgb => colors.map(<[_]>::to_vec),
        ColorMode::Intensity => intensity.map(|i| i.iter().map(|&v| [v; 3]).collect()),
        ColorMode::None => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::SplitMix64;

    #[test]
    fn the_weight_is_smooth_and_compact() {
        assert_eq!(weight(0.0, 1.0), 1.0);
        assert_eq!(weight(1.0, 1.0), 0.0);
        assert_eq!(weight(4.0, 1.0), 0.0);
        // Decreasing inside the support.
        let w: Vec<f64> = (0..10)
            .map(|k| weight((k as f64 / 10.0).powi(2), 1.0))
            .collect();
        assert!(w.windows(2).all(|p| p[1] < p[0]), "{w:?}");
    }

    #[test]
    fn a_linear_colour_field_is_reproduced_between_the_points() {
        // Dense points on a plane with colour linear in x: a symmetric blend reproduces a linear
        // field at interior vertices (up to the sampling's asymmetry).
        let mut rng = SplitMix64(5);
        let pts: Vec<Point3> = (0..100_000)
            .map(|_| [rng.next_f64(), rng.next_f64(), 0.0])
            .collect();
        let vals: Vec<[f32; 3]> = pts.iter().map(|p| [p[0] as f32, 0.25, 1.0]).collect();
        let verts: Vec<Point3> = (1..10)
            .flat_map(|i| (1..10).map(move |j| [0.1 * i as f64, 0.1 * j as f64, 0.001]))
            .collect();
        let c = vertex_colors(&verts, &pts, &vals, 0.03).unwrap();
        for (v, c) in verts.iter().zip(&c) {
            assert!((f64::from(c[0]) - v[0]).abs() < 0.01, "{v:?} {c:?}");
            assert!((c[1] - 0.25).abs() < 1e-6 && (c[2] - 1.0).abs() < 1e-6);
        }
        // A vertex far from every point blends its nearest ones instead of failing.
        let far = vertex_colors(&[[0.5, 0.5, 5.0]], &pts, &vals, 0.03).unwrap();
        assert!((far[0][0] - 0.5).abs() < 0.2 && (far[0][1] - 0.25).abs() < 1e-6);
    }

    #[test]
    fn not_the_nearest_point_only() {
        // Two points, one red one blue, the vertex nearer the red one: the blend is mostly red
        // but has blue in it (a nearest-point colouring would give pure red).
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let vals = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let c = vertex_colors(&[[0.4, 0.0, 0.0]], &pts, &vals, 2.0).unwrap()[0];
        assert!(c[0] > 0.5 && c[2] > 0.1 && c[0] + c[2] > 0.999, "{c:?}");
        assert_eq!(
            "intensity".parse::<ColorMode>().unwrap(),
            ColorMode::Intensity
        );
        assert!("gray".parse::<ColorMode>().is_err());
    }
}
