//! Whether the data surround their middle: the widest cone of directions, seen from the centroid
//! and from the bounding-box centre, that holds no point. Data taken all around an object leave
//! only narrow empty cones (holes from occlusion, oceans between continents), even when much of
//! the surface is missing; a single-view range scan leaves the half-space behind it empty and an
//! open scene the sky above it.
//!
//! Measured on the real-scan suite (half-angles, the smaller of the two centres): closed objects
//! 6–17° (kitten 7°, man 6°, elephant 7°, camel 11°, armadillo 12°, radar — land only, on a
//! sphere — 15°, oni 17°), open data 34–57° (outdoor scene b9 34°, clusters poste_france 45°,
//! building on a ground patch 54°, hippo partial scans 56–57°, bun000 range image 56°).

use super::{Aabb, Point3, dot, norm, sub};
use rayon::prelude::*;

/// Directions tried (a spherical Fibonacci set: about 6.4° apart).
const DIRECTIONS: usize = 1000;

/// Most points looked at (every k-th beyond this many).
const MAX_POINTS: usize = 50_000;

/// Half-angle (radians) of the widest cone of directions from `centre` that holds no point of
/// `points`, found among [`DIRECTIONS`] axes (so about 3° low at worst); π when every point is
/// at `centre` or there are none.
pub fn largest_empty_cone(points: &[Point3], centre: Point3) -> f64 {
    let step = points.len().div_ceil(MAX_POINTS).max(1);
    let dirs: Vec<Point3> = (points.iter().step_by(step))
        .filter_map(|p| {
            let d = sub(*p, centre);
            let l = norm(d);
            (l > 0.0).then(|| d.map(|v| v / l))
        })
        .collect();
    if dirs.is_empty() {
        return std::f64::consts::PI;
    }
    (0..DIRECTIONS)
        .into_par_iter()
        .map(|i| {
            let axis = fibonacci_direction(i, DIRECTIONS);
            let nearest = dirs.iter().map(|d| dot(*d, axis)).fold(-1.0, f64::max);
            nearest.clamp(-1.0, 1.0).acos()
        })
        .reduce(|| 0.0, f64::max)
}

/// Half-angle (radians) of the widest empty cone seen from the better of the two middles of the
/// data (the centroid and the bounding-box centre): small when the data surround the object.
pub fn surround_cone(points: &[Point3]) -> f64 {
    if points.is_empty() {
        return std::f64::consts::PI;
    }
    let n = points.len() as f64;
    let centroid: Point3 = std::array::from_fn(|k| points.iter().map(|p| p[k]).sum::<f64>() / n);
    let centre = Aabb::from_points(points).center();
    largest_empty_cone(points, centroid).min(largest_empty_cone(points, centre))
}

/// Direction `i` of `n` spread evenly over the unit sphere (a Fibonacci lattice).
pub(crate) fn fibonacci_direction(i: usize, n: usize) -> Point3 {
    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f64::consts::PI * (1.0 + 5f64.sqrt()) * i as f64;
    [r * phi.cos(), r * phi.sin(), z]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::Shape;

    #[test]
    fn a_sphere_surrounds_its_centre_and_a_hemisphere_leaves_half_empty() {
        let sphere = Shape::by_name("sphere").unwrap().sample(4000, 3).points;
        assert!(surround_cone(&sphere).to_degrees() < 10.0);
        // The upper half only: both middles lie on the axis about r/2 above the equator, from
        // where the rim is atan(2) = 63.4° off the downward axis.
        let c = Aabb::from_points(&sphere).center();
        let cap: Vec<Point3> = sphere.iter().copied().filter(|p| p[2] > c[2]).collect();
        let cone = surround_cone(&cap).to_degrees();
        assert!(cone > 55.0 && cone < 70.0, "{cone}");
    }

    #[test]
    fn the_widest_empty_cone_matches_a_brute_force_over_a_finer_set() {
        // Points on a sphere with a polar cap of 40° removed: the empty cone is the cap.
        let sphere = Shape::by_name("sphere").unwrap().sample(6000, 5).points;
        let c = Aabb::from_points(&sphere).center();
        let cut = 40f64.to_radians().cos();
        let kept: Vec<Point3> = (sphere.iter().copied())
            .filter(|p| {
                let d = sub(*p, c);
                dot(d, [0.0, 0.0, 1.0]) / norm(d) < cut
            })
            .collect();
        let cone = largest_empty_cone(&kept, c).to_degrees();
        assert!((cone - 40.0).abs() < 4.0, "{cone}");
        let brute = (0..20_000)
            .map(|i| {
                let a = fibonacci_direction(i, 20_000);
                let near = kept.iter().map(|p| {
                    let d = sub(*p, c);
                    dot(d, a) / norm(d)
                });
                near.fold(-1.0, f64::max).acos().to_degrees()
            })
            .fold(0.0, f64::max);
        // The finer set finds the widest cone to within ~1°, the coarse one to within ~3°.
        assert!((cone - brute).abs() < 4.0, "{cone} vs {brute}");
    }
}
