//! Inward regions inside a patch. A patch is oriented by a spanning tree of confident edges, and
//! one wrong edge (across a plate thinner than the neighbourhood, where a tilted estimated plane
//! makes the edge look tangent) flips everything beyond it: a region inside a larger patch points
//! inward while the rest points outward, so the patch as a whole still sees a positive mean winding
//! number. Point by point the two are clear apart: on a consistently outward closed surface the
//! winding number is about ½ at every sample, on a flipped region about −½ (measured on the CGAL
//! elk, 10k samples, seed 4: 1,159 flipped points at −0.52…+0.07, median −0.45; the others
//! 0.33…0.59 (5–95 %), median 0.48).
//!
//! So the winding number is evaluated at an even stride of at most [`REGION_BUDGET`] points (all of
//! them for smaller clouds), carried to the other points along confident edges inside their patch
//! (breadth first from the evaluated points), and every connected region of at least
//! [`MIN_REGION`] points whose winding is below the inward threshold, connected by confident edges
//! inside one patch, is flipped. Pieces of open sheets see between about −¼ and ¼ and are left;
//! a connected component whose mean winding number is near zero (a flat sheet, a scene) encloses
//! nothing and has no inward region at all.

use std::collections::VecDeque;

use super::dipole::{PatchedCloud, winding_at};
use super::graph::Edge;

/// Most points at which the winding number is evaluated.
const REGION_BUDGET: usize = 60_000;
/// Fewest points in a region that is flipped (smaller ones are left to the fit).
const MIN_REGION: usize = 8;
/// Mean winding number over a connected component below which its oriented points enclose
/// nothing (a flat sheet or a scene: measured −0.001 on a noisy 10⁶-point height field, 0.01 on
/// the outdoor scene b9, 0.02 on poste_france), so no region of it is "inward": on such a sheet
/// the winding number at a sample is noise around 0, and at σ ≈ ¼ spacing enough samples fall
/// below the threshold to flip thousands of points in small patches (pinholes in the surface).
/// Closed objects measure 0.35–0.46 (the elk with a flipped region 0.35), partial and open scans
/// of curved objects 0.18–0.32.
const ENCLOSING_MEAN: f64 = 0.1;

/// The points of every inward region (see the module doc), whose normals are to be flipped: points
/// whose winding number is below `threshold`, connected through edges of at least
/// `min_confidence` inside one patch, in groups of at least [`MIN_REGION`].
pub(crate) fn inward_regions(
    cloud: &PatchedCloud,
    edges: &[Edge],
    min_confidence: f64,
    threshold: f64,
) -> Vec<u32> {
    let n = cloud.points.len();
    let mut flip = Vec::new();
    if n == 0 {
        return flip;
    }
    let label = &cloud.patches.label;
    let mut adjacent: Vec<Vec<u32>> = vec![Vec::new(); n];
    for e in edges
        .iter()
        .take_while(|e| e.confidence >= min_confidence)
        .filter(|e| label[e.a as usize] == label[e.b as usize])
    {
        adjacent[e.a as usize].push(e.b);
        adjacent[e.b as usize].push(e.a);
    }
    let step = n.div_ceil(REGION_BUDGET).max(1);
    let targets: Vec<u32> = (0..n as u32).step_by(step).collect();
    let at_targets = winding_at(cloud, &targets);
    let enclosing = enclosing_components(cloud, &targets, &at_targets);
    let winding = spread(&adjacent, &targets, &at_targets);
    let inward: Vec<bool> = (winding.iter().enumerate())
        .map(|(i, &w)| w < threshold && enclosing[cloud.component[label[i] as usize] as usize])
        .collect();
    let mut seen = vec![false; n];
    let mut region = Vec::new();
    for start in 0..n {
        if seen[start] || !inward[start] {
            continue;
        }
        region.clear();
        region.push(start as u32);
        seen[start] = true;
        let mut head = 0;
        while head < region.len() {
            let i = region[head] as usize;
            head += 1;
            for &j in &adjacent[i] {
                if !seen[j as usize] && inward[j as usize] {
                    seen[j as usize] = true;
                    region.push(j);
                }
            }
        }
        if region.len() >= MIN_REGION {
            flip.extend_from_slice(&region);
        }
    }
    flip
}

/// Per connected component, whether its points enclose a volume: the mean winding number at its
/// evaluated points (`targets`, values `at_targets`) is at least [`ENCLOSING_MEAN`].
fn enclosing_components(cloud: &PatchedCloud, targets: &[u32], at_targets: &[f64]) -> Vec<bool> {
    let count = cloud
        .component
        .iter()
        .map(|&c| c as usize + 1)
        .max()
        .unwrap_or(0);
    let mut sum = vec![(0.0, 0usize); count];
    for (&i, &w) in targets.iter().zip(at_targets) {
        let c = cloud.component[cloud.patches.label[i as usize] as usize] as usize;
        sum[c].0 += w;
        sum[c].1 += 1;
    }
    sum.iter()
        .map(|&(s, n)| n > 0 && s / n as f64 >= ENCLOSING_MEAN)
        .collect()
}

/// Per point, the value of the nearest (in hops over `adjacent`) of the `sources`; `+∞` where none
/// is reachable. Ties go to the source listed first.
fn spread(adjacent: &[Vec<u32>], sources: &[u32], values: &[f64]) -> Vec<f64> {
    let mut out = vec![f64::INFINITY; adjacent.len()];
    let mut reached = vec![false; adjacent.len()];
    let mut queue = VecDeque::new();
    for (&s, &v) in sources.iter().zip(values) {
        out[s as usize] = v;
        reached[s as usize] = true;
        queue.push_back(s);
    }
    while let Some(i) = queue.pop_front() {
        for &j in &adjacent[i as usize] {
            if !reached[j as usize] {
                reached[j as usize] = true;
                out[j as usize] = out[i as usize];
                queue.push_back(j);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point3;
    use crate::normals::patches::Patches;

    #[test]
    fn values_spread_to_the_nearest_source_and_not_across_gaps() {
        // Chain 0-1-2-3-4, and 5 alone.
        let adjacent = vec![vec![1], vec![0, 2], vec![1, 3], vec![2, 4], vec![3], vec![]];
        let out = spread(&adjacent, &[0, 4], &[1.0, 2.0]);
        assert_eq!(&out[..5], &[1.0, 1.0, 1.0, 2.0, 2.0]);
        assert_eq!(out[5], f64::INFINITY);
    }

    /// A thin torus in one patch with both faces of one section of its tube flipped inward (what
    /// one wrong edge across a thin plate does): the section is flipped back, except for its two
    /// ends, where the winding number passes through 0; nothing outside it is touched, and
    /// consistent normals are left alone.
    #[test]
    fn a_flipped_section_of_a_thin_tube_is_flipped_back() {
        use crate::geometry::{dot, norm, sub, synthetic::Shape};
        let n = 3000;
        let shape = Shape::Torus {
            center: [0.5; 3],
            major: 0.3,
            minor: 0.04,
        };
        let cloud = shape.sample(n, 2);
        let truth = cloud.normals.unwrap();
        let points = cloud.points;
        let mut edges = Vec::new();
        for (a, p) in points.iter().enumerate() {
            let mut near: Vec<(f64, usize)> = (0..n)
                .filter(|&b| b != a)
                .map(|b| (norm(sub(points[b], *p)), b))
                .collect();
            near.sort_by(|x, y| x.0.total_cmp(&y.0));
            for &(_, b) in &near[..8] {
                let (a, b) = (a as u32, b as u32);
                edges.push(Edge {
                    a,
                    b,
                    agree: true,
                    confidence: 1.0,
                });
            }
        }
        let area = 4.0 * std::f64::consts::PI.powi(2) * 0.3 * 0.04 / n as f64;
        let areas = vec![area; n];
        let patches = Patches {
            label: vec![0; n],
            count: 1,
        };
        let run = |normals: &[Point3]| {
            let cloud = PatchedCloud {
                points: &points,
                normals,
                areas: &areas,
                patches: &patches,
                component: &[0],
            };
            let flip = inward_regions(&cloud, &edges, 0.966, -0.3);
            let mut out = normals.to_vec();
            for &i in &flip {
                out[i as usize] = out[i as usize].map(|v| -v);
            }
            (flip.len(), out)
        };
        let (flipped, out) = run(&truth);
        assert_eq!(flipped, 0);
        assert_eq!(out, truth);
        // The section within 60° of +x: a third of the tube.
        let section: Vec<bool> = points.iter().map(|p| p[0] - 0.5 > 0.15).collect();
        let bad: Vec<Point3> = truth
            .iter()
            .zip(&section)
            .map(|(t, &c)| if c { t.map(|v| -v) } else { *t })
            .collect();
        let (flipped, out) = run(&bad);
        let in_section = section.iter().filter(|&&c| c).count();
        assert!(in_section > 800, "{in_section} points in the section");
        let right = |i: usize| dot(out[i], truth[i]) > 0.0;
        let outside_touched = (0..n).filter(|&i| !section[i] && !right(i)).count();
        assert_eq!(outside_touched, 0);
        let fixed = (0..n).filter(|&i| section[i] && right(i)).count();
        assert_eq!(flipped, fixed);
        assert!(
            fixed * 10 >= in_section * 8,
            "{fixed} of {in_section} flipped back"
        );
    }
}
