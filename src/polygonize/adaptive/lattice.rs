//! The adaptive extractor's lattice (fine nodes, coarse cubes, bricks, tiles) and its store of
//! field values, gradients and prepared tiles.

use std::collections::{BTreeMap, HashMap};
use std::hash::BuildHasherDefault;

use rayon::prelude::*;

use super::super::extract::EdgeIdHasher;
use super::super::tets::Node;
use super::super::{RegionField, ScalarField};
use crate::geometry::{Aabb, Point3};

/// Coarse cubes per brick edge (a brick is 16 grid cells, the uniform extractor's block).
pub(super) const BRICK: i64 = 8;

pub(super) type FastMap<V> = HashMap<u64, V, BuildHasherDefault<EdgeIdHasher>>;

/// The two-level lattice: fine nodes at `origin + h · n`, coarse cubes of 2 cells.
pub(super) struct Lattice {
    pub(super) origin: Point3,
    pub(super) h: f64,
    /// Coarse cubes per axis.
    pub(super) cubes: [i64; 3],
}

impl Lattice {
    pub(super) fn point(&self, n: Node) -> Point3 {
        [0, 1, 2].map(|k| self.origin[k] + n[k] as f64 * self.h)
    }
    pub(super) fn id(&self, n: Node) -> u64 {
        let d = self.cubes.map(|c| 2 * c as u64 + 1);
        n[0] as u64 + d[0] * (n[1] as u64 + d[1] * n[2] as u64)
    }
    pub(super) fn cube_id(&self, c: [i64; 3]) -> u64 {
        let d = self.cubes.map(|c| c as u64);
        c[0] as u64 + d[0] * (c[1] as u64 + d[1] * c[2] as u64)
    }
    pub(super) fn cube_of(&self, id: u64) -> [i64; 3] {
        let d = self.cubes.map(|c| c as u64);
        [id % d[0], (id / d[0]) % d[1], id / (d[0] * d[1])].map(|x| x as i64)
    }
    pub(super) fn has_cube(&self, c: [i64; 3]) -> bool {
        (0..3).all(|k| c[k] >= 0 && c[k] < self.cubes[k])
    }
    pub(super) fn cube_box(&self, c: [i64; 3]) -> Aabb {
        Aabb {
            min: self.point(c.map(|x| 2 * x)),
            max: self.point(c.map(|x| 2 * x + 2)),
        }
    }
    pub(super) fn bricks(&self) -> [i64; 3] {
        self.cubes.map(|c| (c + BRICK - 1) / BRICK)
    }
    /// The brick whose closed box holds node `n`.
    pub(super) fn brick_of(&self, n: Node) -> [i64; 3] {
        let b = self.bricks();
        [0, 1, 2].map(|k| (n[k] / (2 * BRICK)).min(b[k] - 1))
    }
    /// The tile (4³ grid cells, 2³ cubes) whose closed box holds node `n`.
    pub(super) fn tile_of(&self, n: Node) -> [i64; 3] {
        [0, 1, 2].map(|k| (n[k] / 4).min((self.cubes[k] + 1) / 2 - 1))
    }
    pub(super) fn tile_box(&self, t: [i64; 3]) -> Aabb {
        Aabb {
            min: self.point(t.map(|x| 4 * x)),
            max: self.point([0, 1, 2].map(|k| (4 * (t[k] + 1)).min(2 * self.cubes[k]))),
        }
    }
    pub(super) fn brick_box(&self, b: [i64; 3]) -> Aabb {
        Aabb {
            min: self.point(b.map(|x| 2 * BRICK * x)),
            max: self.point([0, 1, 2].map(|k| (2 * BRICK * (b[k] + 1)).min(2 * self.cubes[k]))),
        }
    }
}

/// Field values and gradients at lattice nodes (NaN stored as +∞: outside), and the field
/// prepared for each tile (4³ grid cells) evaluated so far, kept so that each tile gathers its
/// lists once for probing, following, splitting and placing vertices.
pub(super) struct Samples<'a> {
    pub(super) values: FastMap<f64>,
    pub(super) gradients: FastMap<Point3>,
    pub(super) prepared: HashMap<[i64; 3], Box<dyn RegionField + 'a>>,
    pub(super) evaluations: u64,
}

/// A node's id and its new value and gradient (`None`: known before or not asked).
type Evaluated = (u64, Option<f64>, Option<Point3>);

/// One tile's share of an evaluation: its prepared field and its nodes.
pub(super) type TileWork<'a, T> = ([i64; 3], Box<dyn RegionField + 'a>, Vec<T>);

impl<'a> Samples<'a> {
    /// The tiles of `items` (by `tile`), each with its prepared field taken out of the cache.
    pub(super) fn take<T>(
        &mut self,
        field: &'a dyn ScalarField,
        lat: &Lattice,
        items: BTreeMap<[i64; 3], Vec<T>>,
    ) -> Vec<TileWork<'a, T>> {
        (items.into_iter())
            .map(|(t, v)| {
                let p =
                    (self.prepared.remove(&t)).unwrap_or_else(|| field.prepare(&lat.tile_box(t)));
                (t, p, v)
            })
            .collect()
    }

    /// Puts the prepared fields of `work` back into the cache.
    pub(super) fn give_back<T>(&mut self, work: Vec<TileWork<'a, T>>) {
        for (t, p, _) in work {
            self.prepared.insert(t, p);
        }
    }

    /// Evaluates the values (and with `gradients` the gradients) of `nodes` not known yet,
    /// grouped by tile, in parallel.
    pub(super) fn evaluate(
        &mut self,
        field: &'a dyn ScalarField,
        lat: &Lattice,
        nodes: &[Node],
        gradients: bool,
    ) {
        let mut groups: BTreeMap<[i64; 3], Vec<Node>> = BTreeMap::new();
        for &n in nodes {
            let id = lat.id(n);
            if !self.values.contains_key(&id) || gradients && !self.gradients.contains_key(&id) {
                groups.entry(lat.tile_of(n)).or_default().push(n);
            }
        }
        let mut work = self.take(field, lat, groups);
        let (values, grads) = (&self.values, &self.gradients);
        let results: Vec<Vec<Evaluated>> = work
            .par_iter_mut()
            .map(|(_, prepared, ns)| {
                ns.sort_unstable();
                ns.dedup();
                let ids: Vec<u64> = ns.iter().map(|&n| lat.id(n)).collect();
                let (mut vp, mut vi, mut gp, mut gi) = (vec![], vec![], vec![], vec![]);
                for (i, (&n, id)) in ns.iter().zip(&ids).enumerate() {
                    if !values.contains_key(id) {
                        vp.push(lat.point(n));
                        vi.push(i);
                    }
                    if gradients && !grads.contains_key(id) {
                        gp.push(lat.point(n));
                        gi.push(i);
                    }
                }
                let mut out: Vec<Evaluated> = ids.iter().map(|&id| (id, None, None)).collect();
                let mut v = vec![0.0; vp.len()];
                prepared.values(&vp, &mut v);
                for (&i, f) in vi.iter().zip(v) {
                    out[i].1 = Some(if f.is_nan() { f64::INFINITY } else { f });
                }
                let mut g = vec![[0.0; 3]; gp.len()];
                prepared.gradients(&gp, &mut g);
                for (&i, g) in gi.iter().zip(g) {
                    out[i].2 = Some(g);
                }
                out
            })
            .collect();
        self.give_back(work);
        for (id, v, g) in results.into_iter().flatten() {
            if let Some(v) = v {
                self.values.insert(id, v);
                self.evaluations += 1;
            }
            if let Some(g) = g {
                self.gradients.insert(id, g);
            }
        }
    }

    pub(super) fn value(&self, lat: &Lattice, n: Node) -> f64 {
        self.values[&lat.id(n)]
    }
}

/// The 8 corners of cube `c` (fine nodes), corner bits `x + 2y + 4z`.
pub(super) fn corners(c: [i64; 3]) -> [Node; 8] {
    std::array::from_fn(|m| [0, 1, 2].map(|k| 2 * c[k] + 2 * ((m as i64 >> k) & 1)))
}

/// The 27 fine nodes of cube `c`.
pub(super) fn fine_nodes(c: [i64; 3]) -> impl Iterator<Item = Node> {
    (0..27)
        .map(move |m| [m % 3, (m / 3) % 3, m / 9].map(|x| x as i64))
        .map(move |d| [0, 1, 2].map(|k| 2 * c[k] + d[k]))
}
