//! Volume modelling on fitted fields (the seed's function representation, F-rep): saved fields,
//! a small HyperFun-like expression language (primitives, R-function set operations, blends,
//! offsets, affine maps), polygonization of a composite with the sparse polygonizer, metamorphosis
//! between two fields and voxelization into volume data.
//!
//! Sign convention of this module: **F-rep, `F ≥ 0` inside** (as in HyperFun and the seed), in the
//! input's units. A saved field stores rbfsurf's own convention (`f < 0` inside, normalised units);
//! as an operand it is evaluated as `F(x) = −f(N(x)) / s` with `N` the normalisation and `s` its
//! scale, so near the surface `F` is about a signed distance in input units.
//!
//! One algorithm a file: [`format`] (the `.field` file), [`expr`] (parser), [`ops`] (evaluation and
//! the bounds that drive the polygonizer's skip test), [`mesh`] (polygonize a composite),
//! [`morph`], [`voxel`].

pub mod expr;
pub mod format;
pub(crate) mod mesh;
pub mod morph;
pub(crate) mod ops;
pub mod voxel;

use crate::geometry::{Aabb, Normalization, Point3};
use crate::polygonize::ScalarField;
use crate::rbf::RbfField;
use crate::spatial::IndexKind;
use std::sync::Arc;

pub use expr::{Expr, parse};
pub use mesh::{CsgParams, CsgReport, mesh_solid};
pub use morph::{Align, MorphParams, MorphReport, morph};
pub use ops::{Bound, Solid};
pub use voxel::{VoxelGrid, VoxelParams, voxelize};

/// Errors of volume modelling: reading or parsing operands, evaluating, meshing, writing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FrepError {
    /// A field file could not be read.
    #[error("{path}: cannot read the field file: {message}")]
    Read {
        /// The file.
        path: String,
        /// The OS error.
        message: String,
    },
    /// The file is not a field file, is truncated or corrupt.
    #[error("{path}: not a valid rbfsurf field file: {message}")]
    Corrupt {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The file was written by another version of the format.
    #[error(
        "{path}: field format version {found} is not supported (this rbfsurf reads version {supported}); re-run the reconstruction with --save-field"
    )]
    Version {
        /// The file.
        path: String,
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        supported: u32,
    },
    /// The expression does not parse.
    #[error("expression: {message} at column {column}")]
    Syntax {
        /// What was expected.
        message: String,
        /// 1-based column of the problem.
        column: usize,
    },
    /// Unknown operation or primitive.
    #[error(
        "expression: unknown operation '{name}' at column {column} (known: sphere, box, cylinder, torus, union, intersection, difference, blend, offset, translate, scale, rotate)"
    )]
    UnknownOperation {
        /// The name.
        name: String,
        /// 1-based column.
        column: usize,
    },
    /// An operation got the wrong number or kind of arguments.
    #[error("expression: {name} at column {column} takes {expected}, got {got}")]
    Arity {
        /// The operation.
        name: String,
        /// 1-based column.
        column: usize,
        /// What it takes.
        expected: &'static str,
        /// What it got.
        got: String,
    },
    /// A numeric argument out of range.
    #[error("expression: {name} at column {column}: {message}")]
    BadArgument {
        /// The operation.
        name: String,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// The solid is empty (e.g. the intersection of disjoint solids).
    #[error("the result is empty: {0}")]
    Empty(String),
    /// A parameter of a command out of range.
    #[error("invalid parameter {name} = {value}: {expected}")]
    Param {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: String,
        /// What is allowed.
        expected: &'static str,
    },
    /// Rebuilding a spatial index failed.
    #[error(transparent)]
    Spatial(#[from] crate::spatial::SpatialError),
    /// Polygonization failed.
    #[error(transparent)]
    Polygonize(#[from] crate::polygonize::PolygonizeError),
    /// Writing an output failed.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}

impl FrepError {
    /// Whose failure this is, for the HTTP status and the command line.
    pub fn kind(&self) -> crate::error::ErrorKind {
        use crate::error::ErrorKind;
        match self {
            FrepError::Read { .. } | FrepError::Io(_) => ErrorKind::Internal,
            FrepError::Corrupt { .. } | FrepError::Version { .. } => ErrorKind::InvalidInput,
            FrepError::Empty(_) => ErrorKind::Unreconstructable,
            FrepError::Polygonize(crate::polygonize::PolygonizeError::Cancelled) => {
                ErrorKind::Cancelled
            }
            FrepError::Polygonize(crate::polygonize::PolygonizeError::GridTooLarge { .. }) => {
                ErrorKind::TooLarge
            }
            _ => ErrorKind::BadParameter,
        }
    }
}

/// A fitted CSRBF field with what it takes to evaluate it in the input's units and to save it:
/// the field (normalised units, `f < 0` inside), the normalisation, the data points (normalised,
/// the carrier's index is built over them) and the index settings every index was built with
/// (rebuilt identically on load, so evaluation is bit for bit the same).
pub struct FieldModel {
    /// The field, normalised units.
    pub rbf: Arc<RbfField>,
    /// Input units ↔ normalised units.
    pub normalization: Normalization,
    /// Cleaned data points, normalised units.
    pub points: Vec<Point3>,
    /// Index kind of every index of the field.
    pub index: IndexKind,
    /// Octree leaf size of every index.
    pub leaf_size: usize,
}

impl FieldModel {
    /// F-rep value in input units: `F(x) = −f(N(x)) / s` (≥ 0 inside, about a signed distance in
    /// input units near the surface).
    pub fn value(&self, x: &Point3) -> f64 {
        -self.rbf.value(&self.normalization.forward(x)) / self.normalization.scale
    }

    /// Bounding box of the data points, input units.
    pub fn data_bounds(&self) -> Aabb {
        let b = Aabb::from_points(&self.points);
        Aabb {
            min: self.normalization.inverse(&b.min),
            max: self.normalization.inverse(&b.max),
        }
    }

    /// Box outside which the field is the carrier alone: the data box and the carrier's own zero set
    /// grown by one finest support radius, input units. Outside it the surface cannot pass for
    /// the analytic carriers; a local carrier's zero set can continue beyond the data (an open
    /// scan), which is then cut at this box.
    pub fn domain(&self) -> Aabb {
        let mut b = Aabb::from_points(&self.points);
        if let Some(c) = self.rbf.carrier.zero_set_bounds() {
            b.grow(&c.min);
            b.grow(&c.max);
        }
        let b = b.inflated(self.rbf.finest_support);
        Aabb {
            min: self.normalization.inverse(&b.min),
            max: self.normalization.inverse(&b.max),
        }
    }
}
