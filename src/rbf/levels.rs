//! The coarse-to-fine hierarchy of a multi-level CSRBF fit, after Floater & Iske (1996,
//! "Multistep scattered data interpolation using compactly supported radial basis functions") and
//! Ohtake, Belyaev & Seidel (2003–2005, multi-scale CSRBF): level `l` uses support radius
//! `R_l = R · 2^(L−1−l)` (halving per level, `R` the finest radius) and a subset of the points thinned
//! on a grid whose cell matches that radius, so every level's matrix has about the same number of
//! non-zeros per row (sparse and well conditioned) and the levels together hold about `4/3 n`
//! centres on a surface. Level `l` interpolates what the carrier and the levels before it left.
//!
//! Density adaptivity: a point whose local spacing (distance to its 8th neighbour) exceeds a
//! level's radius takes no part in that or any finer level (its support there would see no
//! neighbour); it is a centre of the finest level that still sees its neighbourhood. In sparse
//! regions the effective support is therefore the larger radius the spacing calls for, in dense
//! regions the finest one.
//!
//! Thinning is `O(n)` per level (hash of grid cells); the spacing query `O(n log n)`.

use crate::geometry::Point3;
use crate::spatial::SpatialIndex;
use rayon::prelude::*;
use std::collections::HashMap;

/// Neighbour rank that defines a point's local spacing for density adaptivity.
const SPACING_RANK: usize = 8;

/// One planned level: its centres (indices into the points) and support radius.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelPlan {
    /// Indices of the centres of this level, ascending.
    pub members: Vec<u32>,
    /// Support radius `R_l`, normalised units.
    pub radius: f64,
}

/// Plan `count` levels (coarse → fine) over `points` with finest radius `radius` (normalised
/// units) that holds about `neighbours` points. The finest level holds every point whose local
/// spacing its radius covers; each coarser level thins the next finer one on a grid of cell
/// `R_l · √(π / neighbours)` (one point per cell, the one nearest the cell centre, so a level's
/// support again holds about `neighbours` centres on a surface) and adds the points that are too
/// sparse for any finer level.
pub fn plan_levels(
    points: &[Point3],
    index: &dyn SpatialIndex,
    radius: f64,
    neighbours: f64,
    count: usize,
) -> Vec<LevelPlan> {
    let n = points.len();
    if count <= 1 || n == 0 {
        return vec![LevelPlan {
            members: (0..n as u32).collect(),
            radius,
        }];
    }
    let local: Vec<f64> = points
        .par_iter()
        .map_init(Vec::new, |knn, p| {
            index.nearest_k(p, SPACING_RANK + 1, knn);
            knn.last().map_or(0.0, |&(_, d)| d)
        })
        .collect();
    let radii: Vec<f64> = (0..count)
        .map(|l| radius * (1u64 << (count - 1 - l)) as f64)
        .collect();
    // own[i] = finest level whose radius covers point i's spacing (0 when none does).
    let own: Vec<usize> = local
        .iter()
        .map(|&s| (0..count).rev().find(|&l| radii[l] >= s).unwrap_or(0))
        .collect();
    let mut plans: Vec<LevelPlan> = Vec::with_capacity(count);
    let mut members: Vec<u32> = (0..n as u32)
        .filter(|&i| own[i as usize] == count - 1)
        .collect();
    plans.push(LevelPlan {
        members: members.clone(),
        radius: radii[count - 1],
    });
    for l in (0..count - 1).rev() {
        let cell = radii[l] * (std::f64::consts::PI / neighbours.max(4.0)).sqrt();
        let mut next = thin(points, &members, cell);
        next.extend((0..n as u32).filter(|&i| own[i as usize] == l));
        next.sort_unstable();
        next.dedup();
        members = next;
        plans.push(LevelPlan {
            members: members.clone(),
            radius: radii[l],
        });
    }
    plans.reverse();
    plans
}

/// One member per occupied grid cell of size `cell`: the one nearest the cell's centre.
fn thin(points: &[Point3], members: &[u32], cell: f64) -> Vec<u32> {
    let inv = 1.0 / cell;
    let mut best: HashMap<[i64; 3], (f64, u32)> = HashMap::with_capacity(members.len() / 4 + 1);
    for &i in members {
        let p = points[i as usize];
        let key = [
            (p[0] * inv).floor() as i64,
            (p[1] * inv).floor() as i64,
            (p[2] * inv).floor() as i64,
        ];
        let d2: f64 = (0..3)
            .map(|k| {
                let c = (key[k] as f64 + 0.5) * cell;
                (p[k] - c) * (p[k] - c)
            })
            .sum();
        let e = best.entry(key).or_insert((f64::INFINITY, i));
        if d2 < e.0 {
            *e = (d2, i);
        }
    }
    let mut out: Vec<u32> = best.into_values().map(|(_, i)| i).collect();
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::Shape;
    use crate::spatial::{IndexKind, build_index};

    #[test]
    fn levels_are_nested_halving_and_cover_every_point() {
        let cloud = Shape::by_name("sphere").unwrap().sample(8000, 3);
        let idx = build_index(&cloud.points, IndexKind::KdTree, 16).unwrap();
        let plans = plan_levels(&cloud.points, idx.as_ref(), 0.06, 30.0, 3);
        assert_eq!(plans.len(), 3);
        assert_eq!(plans[2].members.len(), 8000);
        for w in plans.windows(2) {
            assert!((w[0].radius - 2.0 * w[1].radius).abs() < 1e-15);
            assert!(2 * w[1].members.len() > 3 * w[0].members.len());
            let fine: std::collections::HashSet<u32> = w[1].members.iter().copied().collect();
            assert!(w[0].members.iter().all(|i| fine.contains(i)), "nested");
        }
        // Thinning leaves at most one centre per grid cell of the level's spacing.
        let cell = 0.24 * (std::f64::consts::PI / 30.0).sqrt();
        let mut seen = std::collections::HashSet::new();
        for &i in &plans[0].members {
            let p = cloud.points[i as usize];
            assert!(seen.insert([0, 1, 2].map(|k| (p[k] / cell).floor() as i64)));
        }
    }

    #[test]
    fn sparse_points_stay_at_coarse_levels_and_are_never_lost() {
        let mut cloud = Shape::by_name("sphere").unwrap().sample(6000, 4);
        // A sparse patch: keep only every 20th point with z > 0.7.
        let pts: Vec<Point3> = cloud
            .points
            .iter()
            .enumerate()
            .filter(|(i, p)| p[2] <= 0.7 || i % 20 == 0)
            .map(|(_, p)| *p)
            .collect();
        cloud.points = pts;
        let idx = build_index(&cloud.points, IndexKind::KdTree, 16).unwrap();
        let plans = plan_levels(&cloud.points, idx.as_ref(), 0.03, 30.0, 3);
        let fine: std::collections::HashSet<u32> = plans[2].members.iter().copied().collect();
        let sparse: Vec<u32> = (0..cloud.points.len() as u32)
            .filter(|&i| cloud.points[i as usize][2] > 0.75)
            .collect();
        assert!(!sparse.is_empty());
        assert!(
            sparse.iter().all(|i| !fine.contains(i)),
            "sparse points skip the finest level"
        );
        let mut all: Vec<u32> = plans.iter().flat_map(|p| p.members.clone()).collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(
            all.len(),
            cloud.points.len(),
            "every point is a centre somewhere"
        );
    }
}
