//! Block decomposition with a partition of unity, so a large scan is fitted as independent units of
//! work (after Ohtake et al.'s multi-level partition of unity implicits, 2003, and Tobor, Reuter &
//! Schlick's multi-scale PoU RBF, 2004).
//!
//! The points' bounding cube is split like an octree until every leaf's *core* box holds at most
//! `max_points` points; each non-empty leaf is a block whose *outer* box is its core inflated by an
//! overlap `δ`. A block fits its own spline `U_b` to every point inside its outer box (one CSRBF
//! system, single- or multi-level, solved and freed before the next), and the field is
//! `f = g + Σ_b w_b U_b / Σ_b w_b` with flat-top weights: `w_b = 1` in the core, falling to 0
//! across the overlap with the quintic smootherstep (C², so the blend is C² where the splines are).
//! Interpolation survives the blend: every data point lies in the outer box of each block whose
//! weight is non-zero there, and each of those splines interpolates it. With `δ` at least the
//! largest support radius the blend is continuous where a block borders empty space (its spline
//! is zero there). A block needs only its points and their carrier offsets, which is what a
//! distributed engine would ship.
//!
//! Planning is `O(n · depth)`; gathering members `O(n · blocks)`, in parallel.

use super::field::Spline;
use crate::geometry::{Aabb, Point3};
use rayon::prelude::*;

/// How the CSRBF system is decomposed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Blocks {
    /// One global system below 250,000 points, blocks of at most 250,000 points above.
    #[default]
    Auto,
    /// One global system whatever the size (the seed's method).
    None,
    /// Blocks of at most this many core points.
    MaxPoints(usize),
}

/// Core points per block that [`Blocks::Auto`] allows.
const AUTO_BLOCK_POINTS: usize = 250_000;

impl Blocks {
    /// Core-point limit per block for `n` points, or `None` for one global system.
    pub fn max_points(self, n: usize) -> Option<usize> {
        match self {
            Blocks::None => None,
            Blocks::Auto if n <= AUTO_BLOCK_POINTS => None,
            Blocks::Auto => Some(AUTO_BLOCK_POINTS),
            Blocks::MaxPoints(m) if n <= m => None,
            Blocks::MaxPoints(m) => Some(m),
        }
    }
}

impl std::str::FromStr for Blocks {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Blocks::Auto),
            "none" => Ok(Blocks::None),
            _ => match s.parse::<usize>() {
                Ok(m) if m >= 1000 => Ok(Blocks::MaxPoints(m)),
                _ => Err(format!(
                    "blocks '{s}': use auto, none or a maximum number of points per block (≥ 1000)"
                )),
            },
        }
    }
}

impl std::fmt::Display for Blocks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Blocks::Auto => f.write_str("auto"),
            Blocks::None => f.write_str("none"),
            Blocks::MaxPoints(m) => write!(f, "{m}"),
        }
    }
}

/// A planned block: its boxes and the points it fits.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockPlan {
    /// The octree leaf (weight 1 inside), normalised units.
    pub core: Aabb,
    /// The core inflated by the overlap (weight 0 outside), normalised units.
    pub outer: Aabb,
    /// Indices of the points inside `outer`, ascending.
    pub members: Vec<u32>,
}

/// A solved block of the partition of unity.
pub struct PouBlock {
    /// Weight 1 inside, normalised units.
    pub core: Aabb,
    /// Weight 0 outside, normalised units.
    pub outer: Aabb,
    /// The block's spline `U_b`.
    pub spline: Spline,
}

impl PouBlock {
    /// `(w_b(x), ∇w_b(x))`: the product over axes of `1 − S(t)`, `t` the distance beyond the core
    /// along that axis over the overlap width, `S` the quintic smootherstep.
    pub fn weight(&self, x: &Point3) -> (f64, Point3) {
        let mut f = [1.0; 3];
        let mut df = [0.0; 3];
        for k in 0..3 {
            let delta = self.core.min[k] - self.outer.min[k];
            let (below, above) = (self.core.min[k] - x[k], x[k] - self.core.max[k]);
            let (d, sign) = if below > 0.0 {
                (below, -1.0)
            } else if above > 0.0 {
                (above, 1.0)
            } else {
                continue;
            };
            if d >= delta {
                return (0.0, [0.0; 3]);
            }
            let t = d / delta;
            f[k] = 1.0 - t * t * t * (10.0 - 15.0 * t + 6.0 * t * t);
            df[k] = -30.0 * t * t * (1.0 - t) * (1.0 - t) * sign / delta;
        }
        (
            f[0] * f[1] * f[2],
            [
                df[0] * f[1] * f[2],
                f[0] * df[1] * f[2],
                f[0] * f[1] * df[2],
            ],
        )
    }
}

/// Split the bounding cube of `points` (centred on their box) (normalised units) into octree leaves of at most
/// `max_points` points (depth ≤ 10), and gather each non-empty leaf's members within `overlap`.
pub fn plan_blocks(points: &[Point3], max_points: usize, overlap: f64) -> Vec<BlockPlan> {
    let leaves = plan_leaves(points, &Aabb::from_points(points), max_points, false);
    leaves
        .into_par_iter()
        .map(|core| {
            let outer = core.inflated(overlap);
            let members = (0..points.len() as u32)
                .filter(|&i| outer.contains(&points[i as usize]))
                .collect();
            BlockPlan {
                core,
                outer,
                members,
            }
        })
        .collect()
}

/// The octree leaves of [`plan_blocks`] over the cube centred on `bounds` (normalised units)
/// with edge its longest side: split until a leaf holds at most `max_points` of `points` (depth
/// ≤ 10), in depth-first order. With `keep_empty` the empty children of a split cell are leaves
/// too, so the leaves tile the cube (when `points` is a subsample of the cloud in `bounds`, every
/// point of the cloud is in a leaf); otherwise they are left out.
pub fn plan_leaves(
    points: &[Point3],
    bounds: &Aabb,
    max_points: usize,
    keep_empty: bool,
) -> Vec<Aabb> {
    let edge = bounds
        .extent()
        .iter()
        .fold(0.0f64, |a, &b| a.max(b))
        .max(1e-9)
        * (1.0 + 1e-9);
    let c = bounds.center();
    let root = Aabb {
        min: c.map(|v| v - 0.5 * edge),
        max: c.map(|v| v + 0.5 * edge),
    };
    let mut leaves = Vec::new();
    let all: Vec<u32> = (0..points.len() as u32).collect();
    let rule = Split {
        points,
        max_points: max_points.max(1),
        keep_empty,
    };
    split(&rule, root, all, 0, &mut leaves);
    leaves
}

/// What the octree split compares against.
struct Split<'a> {
    points: &'a [Point3],
    max_points: usize,
    keep_empty: bool,
}

/// Recursive octree split; a point on a shared face goes to the lower child.
fn split(rule: &Split<'_>, cell: Aabb, inside: Vec<u32>, depth: usize, leaves: &mut Vec<Aabb>) {
    let (points, max_points) = (rule.points, rule.max_points);
    if inside.is_empty() {
        if rule.keep_empty && depth > 0 {
            leaves.push(cell);
        }
        return;
    }
    if inside.len() <= max_points || depth >= 10 {
        leaves.push(cell);
        return;
    }
    let c = cell.center();
    let mut kids: [Vec<u32>; 8] = Default::default();
    for i in inside {
        let p = points[i as usize];
        let o =
            (p[0] > c[0]) as usize | ((p[1] > c[1]) as usize) << 1 | ((p[2] > c[2]) as usize) << 2;
        kids[o].push(i);
    }
    for (o, kid) in kids.into_iter().enumerate() {
        let pick = |k: usize| {
            if o >> k & 1 == 1 {
                (c[k], cell.max[k])
            } else {
                (cell.min[k], c[k])
            }
        };
        let (x, y, z) = (pick(0), pick(1), pick(2));
        let child = Aabb {
            min: [x.0, y.0, z.0],
            max: [x.1, y.1, z.1],
        };
        split(rule, child, kid, depth + 1, leaves);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::Shape;

    fn block(core: Aabb, overlap: f64) -> PouBlock {
        PouBlock {
            core,
            outer: core.inflated(overlap),
            spline: Spline {
                levels: Vec::new(),
                polynomial: None,
            },
        }
    }

    #[test]
    fn leaves_tile_the_cube_and_respect_the_limit() {
        let cloud = Shape::by_name("torus").unwrap().sample(20_000, 5);
        let plans = plan_blocks(&cloud.points, 3000, 0.05);
        assert!(plans.len() >= 7, "{} blocks", plans.len());
        for p in &cloud.points {
            let cores = plans.iter().filter(|b| b.core.contains(p)).count();
            assert!(cores >= 1, "every point is in a core");
        }
        for b in &plans {
            let core = cloud.points.iter().filter(|p| b.core.contains(p)).count();
            assert!(core <= 3000 + 50, "core holds {core}"); // + points on shared faces
            let brute: Vec<u32> = (0..cloud.points.len() as u32)
                .filter(|&i| b.outer.contains(&cloud.points[i as usize]))
                .collect();
            assert_eq!(brute, b.members);
        }
    }

    #[test]
    fn weights_are_one_in_the_core_zero_outside_and_have_the_right_gradient() {
        let b = block(
            Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            0.2,
        );
        assert_eq!(b.weight(&[0.5, 0.2, 0.9]).0, 1.0);
        assert_eq!(b.weight(&[1.25, 0.5, 0.5]).0, 0.0);
        let x = [1.07, -0.13, 0.4];
        let (w, g) = b.weight(&x);
        assert!(w > 0.0 && w < 1.0);
        let h = 1e-6;
        for k in 0..3 {
            let (mut a, mut c) = (x, x);
            a[k] += h;
            c[k] -= h;
            let fd = (b.weight(&a).0 - b.weight(&c).0) / (2.0 * h);
            assert!((fd - g[k]).abs() < 1e-6, "axis {k}: {fd} vs {}", g[k]);
        }
    }

    #[test]
    fn weights_of_adjacent_blocks_sum_to_at_least_one_inside_the_union() {
        let cloud = Shape::by_name("sphere").unwrap().sample(5000, 6);
        let plans = plan_blocks(&cloud.points, 800, 0.04);
        let blocks: Vec<PouBlock> = plans.iter().map(|p| block(p.core, 0.04)).collect();
        let sum = |p: &Point3| blocks.iter().map(|b| b.weight(p).0).sum::<f64>();
        for p in &cloud.points {
            assert!(sum(p) >= 1.0 - 1e-12, "sum {} at a data point", sum(p));
        }
        // Everywhere in the cores' union, not only at the data: a uniform lattice of 41³ points
        // (off the data, across every shared face and corner of the octree leaves).
        let mut cube = plans[0].core;
        for p in &plans {
            cube.grow(&p.core.min);
            cube.grow(&p.core.max);
        }
        let e = cube.extent();
        for i in 0..=40 {
            for j in 0..=40 {
                for k in 0..=40 {
                    let t = [i, j, k].map(|v| v as f64 / 40.0);
                    let x = [0, 1, 2].map(|a| cube.min[a] + t[a] * e[a]);
                    assert!(sum(&x) >= 1.0 - 1e-12, "sum {} at {x:?}", sum(&x));
                }
            }
        }
    }

    #[test]
    fn names_round_trip_and_auto_splits_only_large_inputs() {
        for b in [Blocks::Auto, Blocks::None, Blocks::MaxPoints(5000)] {
            assert_eq!(b.to_string().parse::<Blocks>(), Ok(b));
        }
        assert!("12".parse::<Blocks>().is_err());
        assert_eq!(Blocks::Auto.max_points(100_000), None);
        assert_eq!(Blocks::Auto.max_points(1_000_000), Some(250_000));
        assert_eq!(Blocks::MaxPoints(5000).max_points(4000), None);
    }
}
