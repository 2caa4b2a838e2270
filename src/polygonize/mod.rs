//! Polygonization: extract the zero set of a scalar field as a closed triangle mesh (3D), or as
//! polylines ([`marching_squares`], 2D curves).
//!
//! Works on any [`ScalarField`] (it knows nothing of RBFs). Convention: `f < 0` inside,
//! `f > 0` outside, so the gradient points outwards and triangles are wound counter-clockwise
//! seen from outside.

use crate::geometry::{Aabb, Point3};

/// A scalar field in normalised units whose zero set is the surface.
pub trait ScalarField: Sync {
    /// `f(p)`: negative inside, positive outside.
    fn value(&self, p: &Point3) -> f64;
    /// `∇f(p)` (points outwards on the surface).
    fn gradient(&self, p: &Point3) -> Point3;
    /// Gradients at `points`, all inside `region`: `out[i] = gradient(points[i])` (up to rounding).
    /// Fields backed by a spatial index override this like [`ScalarField::values_in`].
    /// `out.len() == points.len()`.
    fn gradients_in(&self, region: &Aabb, points: &[Point3], out: &mut [Point3]) {
        let _ = region;
        for (p, o) in points.iter().zip(out.iter_mut()) {
            *o = self.gradient(p);
        }
    }
    /// Values at `points`, all inside `region`: `out[i] = value(points[i])`. Fields backed by a
    /// spatial index override this to gather their candidates once per region. `out.len() == points.len()`.
    fn values_in(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        let _ = region;
        for (p, o) in points.iter().zip(out.iter_mut()) {
            *o = self.value(p);
        }
    }
    /// The field prepared for many evaluations inside `region`: a field backed by a spatial index
    /// gathers its candidates once here instead of once per [`ScalarField::values_in`] call (the
    /// polygonizer probes, samples and refines one tile with one gather). Values and gradients are
    /// those of [`ScalarField::values_in`] and [`ScalarField::gradients_in`] over the same region,
    /// bit for bit. Default: those calls, one per use.
    fn prepare<'a>(&'a self, region: &Aabb) -> Box<dyn RegionField + 'a> {
        Box::new(PerCall {
            field: self,
            region: *region,
        })
    }
    /// Skip test: `false` when the zero set is not expected to meet `cell`, so the polygonizer need
    /// not sample it. Returning `true` always is correct but slow. The polygonizer does not trust a
    /// `false` blindly: a skipped tile that the zero set enters from a sampled neighbour is sampled
    /// after all (see [`polygonize_in`]), so a wrong `false` can only lose pieces of the zero set
    /// that lie entirely in skipped tiles.
    fn may_contain_zero(&self, cell: &Aabb) -> bool;
    /// [`ScalarField::may_contain_zero`] of every cell: `out[i]` for `cells[i]`
    /// (`out.len() == cells.len()`). Fields whose test samples the cells' corners override it
    /// to sample a corner that neighbouring cells share once.
    fn may_contain_zero_each(&self, cells: &[Aabb], out: &mut [bool]) {
        for (c, o) in cells.iter().zip(out.iter_mut()) {
            *o = self.may_contain_zero(c);
        }
    }
}

/// A [`ScalarField`] prepared for evaluations inside one region ([`ScalarField::prepare`]); every
/// point passed must lie inside that region.
pub trait RegionField: Send {
    /// `out[i] = f(points[i])`, as [`ScalarField::values_in`] over the region.
    fn values(&mut self, points: &[Point3], out: &mut [f64]);
    /// `out[i] = ∇f(points[i])`, as [`ScalarField::gradients_in`] over the region.
    fn gradients(&mut self, points: &[Point3], out: &mut [Point3]);
}

/// [`ScalarField::prepare`]'s default: the field's region calls, one per use.
pub(crate) struct PerCall<'a, F: ScalarField + ?Sized> {
    pub(crate) field: &'a F,
    pub(crate) region: Aabb,
}

impl<F: ScalarField + ?Sized> RegionField for PerCall<'_, F> {
    fn values(&mut self, points: &[Point3], out: &mut [f64]) {
        self.field.values_in(&self.region, points, out);
    }

    fn gradients(&mut self, points: &[Point3], out: &mut [Point3]) {
        self.field.gradients_in(&self.region, points, out);
    }
}

/// Where the polygonizer may put triangles: a grid cell is triangulated only when its box
/// [`Region::touches`] the region, and blocks and tiles that do not touch it are not sampled at all.
/// Open scans use [`DataBand`] so that only the band the data support is polygonized.
pub trait Region: Sync {
    /// `false` only when no cell inside `cell` (a cell, tile or block box, normalised units) is kept.
    /// Must be monotone: a box that answers `false` contains no box that answers `true`; the answer
    /// for a cell must depend on its box only (so the mesh is the same whatever the block order).
    fn touches(&self, cell: &Aabb) -> bool;
}

/// The whole domain: every cell is kept.
#[derive(Debug, Clone, Copy, Default)]
pub struct Everywhere;

impl Region for Everywhere {
    fn touches(&self, _cell: &Aabb) -> bool {
        true
    }
}

mod band;
mod block;
mod extract;
mod grid;
mod kuhn;
pub mod marching_squares;
mod params;
mod refine;

pub use band::DataBand;
pub use extract::{polygonize, polygonize_in};
pub use params::{PolygonizeError, PolygonizeParams, PolygonizeStats, Seeding};
