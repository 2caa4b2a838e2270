//! Quality analysis of a 2D zero set against its data (Mann's failure modes as numbers).
//!
//! - components of the zero set (closed loops and chains cut by the sampling box);
//! - extra loops: components with no on-curve data point within the tolerance (Mann's "extra
//!   sheets");
//! - interpolation failures: on-curve data points farther than the tolerance from every component
//!   (Mann's isolated zeros, Fig. 20), and the largest such distance;
//! - `|f(x_i) − v_i|` at the data (exact, independent of the grid);
//! - overshoot: the largest distance of the curve from the data polygon (on-curve samples in the
//!   given order, closed);
//! - signed curvature along the curve, `κ = div(∇f/|∇f|)` from central differences of `f`
//!   (positive where the curve is convex for `f < 0` inside), with its extremes.
//!
//! Cost: `O(d·v)` distances for `d` data points and `v` curve vertices, 9 field evaluations per
//! vertex for the curvature. 3D meshes get their component counts from the mesh stage.

use super::constraints::Sample;
use crate::polygonize::marching_squares::Polyline;

/// Quality figures of a curve (serialised into the workbench report).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CurveQuality {
    /// Connected components of the zero set inside the sampling box.
    pub components: usize,
    /// Components that close inside the box.
    pub closed_loops: usize,
    /// Components with no data point on them (within `tolerance`).
    pub extra_loops: usize,
    /// On-curve data points per component.
    pub data_points_per_component: Vec<usize>,
    /// Rows of on-curve data points farther than `tolerance` from the curve.
    pub interpolation_failures: Vec<usize>,
    /// Largest distance from an on-curve data point to the curve (input units).
    pub max_deviation_at_data: f64,
    /// Largest `|f(x_i) − v_i|` over all samples (field units).
    pub max_abs_residual_at_data: f64,
    /// Largest distance from a curve vertex to the data polygon (input units), when there are
    /// ≥ 3 on-curve points.
    pub max_distance_to_data_polygon: Option<f64>,
    /// Smallest signed curvature on the curve (1/input units).
    pub curvature_min: f64,
    /// Largest signed curvature on the curve.
    pub curvature_max: f64,
    /// Tolerance used (input units).
    pub tolerance: f64,
}

/// Distance from `p` to segment `ab`.
pub fn point_segment_distance(p: &[f64; 2], a: &[f64; 2], b: &[f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// Distance from `p` to a polyline (closing segment included when closed).
pub fn distance_to_polyline(p: &[f64; 2], line: &Polyline) -> f64 {
    let v = &line.points;
    if v.len() == 1 {
        return (p[0] - v[0][0]).hypot(p[1] - v[0][1]);
    }
    let n_seg = if line.closed { v.len() } else { v.len() - 1 };
    (0..n_seg)
        .map(|i| point_segment_distance(p, &v[i], &v[(i + 1) % v.len()]))
        .fold(f64::INFINITY, f64::min)
}

/// Signed curvature of the level set of `f` through `p` (central differences, step `h`).
pub fn level_set_curvature(f: &dyn Fn(&[f64; 2]) -> f64, p: &[f64; 2], h: f64) -> f64 {
    let e = |dx: f64, dy: f64| f(&[p[0] + dx * h, p[1] + dy * h]);
    let f0 = e(0.0, 0.0);
    let (fxp, fxm, fyp, fym) = (e(1.0, 0.0), e(-1.0, 0.0), e(0.0, 1.0), e(0.0, -1.0));
    let fx = (fxp - fxm) / (2.0 * h);
    let fy = (fyp - fym) / (2.0 * h);
    let fxx = (fxp - 2.0 * f0 + fxm) / (h * h);
    let fyy = (fyp - 2.0 * f0 + fym) / (h * h);
    let fxy = (e(1.0, 1.0) - e(1.0, -1.0) - e(-1.0, 1.0) + e(-1.0, -1.0)) / (4.0 * h * h);
    let g2 = fx * fx + fy * fy;
    if g2 == 0.0 {
        return 0.0;
    }
    (fxx * fy * fy - 2.0 * fx * fy * fxy + fyy * fx * fx) / (g2 * g2.sqrt())
}

/// Curvature at every vertex of every polyline (step `h`, input units).
pub fn curvatures(
    f: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    lines: &[Polyline],
    h: f64,
) -> Vec<Vec<f64>> {
    use rayon::prelude::*;
    lines
        .par_iter()
        .map(|l| {
            l.points
                .iter()
                .map(|p| level_set_curvature(f, p, h))
                .collect()
        })
        .collect()
}

/// Analyse `lines` (the zero set of `f`) against `samples`; `kappa` from [`curvatures`].
pub fn analyse(
    f: &(dyn Fn(&[f64; 2]) -> f64 + Sync),
    samples: &[Sample<2>],
    lines: &[Polyline],
    kappa: &[Vec<f64>],
    tolerance: f64,
) -> CurveQuality {
    let on: Vec<(usize, [f64; 2])> = samples
        .iter()
        .enumerate()
        .filter(|(_, s)| s.value == 0.0)
        .map(|(i, s)| (i, s.p))
        .collect();
    let mut per_comp = vec![0usize; lines.len()];
    let mut failures = Vec::new();
    let mut max_dev: f64 = 0.0;
    for &(row, p) in &on {
        let d: Vec<f64> = lines.iter().map(|l| distance_to_polyline(&p, l)).collect();
        let best = d.iter().copied().fold(f64::INFINITY, f64::min);
        max_dev = max_dev.max(best);
        if best > tolerance {
            failures.push(row);
        }
        for (c, &dc) in d.iter().enumerate() {
            if dc <= tolerance {
                per_comp[c] += 1;
            }
        }
    }
    let polygon = (on.len() >= 3).then(|| {
        let poly = Polyline {
            points: on.iter().map(|x| x.1).collect(),
            closed: true,
        };
        lines
            .iter()
            .flat_map(|l| &l.points)
            .map(|p| distance_to_polyline(p, &poly))
            .fold(0.0, f64::max)
    });
    let all_k = kappa.iter().flatten().copied().filter(|k| k.is_finite());
    CurveQuality {
        components: lines.len(),
        closed_loops: lines.iter().filter(|l| l.closed).count(),
        extra_loops: per_comp.iter().filter(|&&c| c == 0).count(),
        data_points_per_component: per_comp,
        interpolation_failures: failures,
        max_deviation_at_data: if on.is_empty() || lines.is_empty() {
            f64::INFINITY
        } else {
            max_dev
        },
        max_abs_residual_at_data: samples
            .iter()
            .map(|s| (f(&s.p) - s.value).abs())
            .fold(0.0, f64::max),
        max_distance_to_data_polygon: polygon,
        curvature_min: all_k.clone().fold(f64::INFINITY, f64::min),
        curvature_max: all_k.fold(f64::NEG_INFINITY, f64::max),
        tolerance,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polygonize::marching_squares::{Grid2, MarchingParams, contour};

    #[test]
    fn circle_quality_is_exact() {
        let f = |p: &[f64; 2]| p[0].hypot(p[1]) - 2.0;
        let g = Grid2 {
            min: [-3.0, -3.0],
            max: [3.0, 3.0],
            nx: 60,
            ny: 60,
        };
        let lines = contour(&f, &g, &MarchingParams::default());
        let samples: Vec<Sample<2>> = (0..8)
            .map(|k| {
                let a = k as f64 * 0.785;
                Sample::on_curve([2.0 * a.cos(), 2.0 * a.sin()], None)
            })
            .collect();
        let k = curvatures(&f, &lines, 1e-4);
        let q = analyse(&f, &samples, &lines, &k, g.cell_diagonal());
        assert_eq!((q.components, q.closed_loops, q.extra_loops), (1, 1, 0));
        assert!(q.interpolation_failures.is_empty());
        assert!(
            q.max_deviation_at_data < 2e-3,
            "{}",
            q.max_deviation_at_data
        );
        assert!(
            (q.curvature_min - 0.5).abs() < 1e-4 && (q.curvature_max - 0.5).abs() < 1e-4,
            "{q:?}"
        );
    }

    #[test]
    fn extra_loop_and_missed_point_are_found() {
        let f = |p: &[f64; 2]| (p[0].hypot(p[1]) - 1.0).min((p[0] - 3.0).hypot(p[1]) - 0.5);
        let g = Grid2 {
            min: [-2.0, -2.0],
            max: [4.0, 2.0],
            nx: 60,
            ny: 40,
        };
        let lines = contour(&f, &g, &MarchingParams::default());
        let samples = vec![
            Sample::on_curve([1.0, 0.0], None),
            Sample::on_curve([0.0, 1.0], None),
            Sample::on_curve([0.0, 1.5], None),
        ];
        let k = curvatures(&f, &lines, 1e-4);
        let q = analyse(&f, &samples, &lines, &k, 0.05);
        assert_eq!((q.components, q.extra_loops), (2, 1));
        assert_eq!(q.interpolation_failures, vec![2]);
        assert!((q.max_deviation_at_data - 0.5).abs() < 1e-3);
    }
}
