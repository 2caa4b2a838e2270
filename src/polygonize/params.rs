//! Parameters, statistics and errors of the polygonizer.

use thiserror::Error;

/// How finely and how far the polygonizer may sample the field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolygonizeParams {
    /// Grid cells along the longest axis of the domain (default 128; 32–1024 is sensible). The cell edge is
    /// `h = longest domain edge / resolution`; the other axes get as many cells of edge `h` as they need.
    pub resolution: usize,
    /// Refuse grids with more cells than this (default 2³²), before allocating anything.
    pub max_cells: u64,
    /// Safeguarded regula-falsi (Illinois) steps that move each vertex onto the zero set after linear
    /// interpolation along its grid edge (default 2; 0 = plain linear interpolation). Each step costs one
    /// field evaluation per vertex.
    pub refine_steps: usize,
    /// Which tiles the zero set is followed from (default [`Seeding::SignChange`]).
    pub seeding: Seeding,
}

impl Default for PolygonizeParams {
    fn default() -> Self {
        PolygonizeParams {
            resolution: 128,
            max_cells: 1 << 32,
            refine_steps: 2,
            seeding: Seeding::SignChange,
        }
    }
}

/// The tiles (4³ cells) the polygonizer samples first; from them it follows the zero set into
/// every neighbouring tile it crosses into, so each connected piece of the zero set that meets one
/// sampled tile's cells is extracted whole either way. The choice only decides which pieces are
/// found at all, and the work spent on tiles the surface does not cross.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Seeding {
    /// Every tile the field's skip test ([`super::ScalarField::may_contain_zero`]) lets through is
    /// sampled: a piece is lost only where that test wrongly answers `false`.
    EveryTile,
    /// A tile the skip test lets through is first probed at its 8 corners and its centre (all
    /// grid nodes, kept as grid values), and sampled only when those 9 values change sign.
    /// The probe nodes of all tiles form a body-centred lattice 4 cells apart; a piece is found
    /// when it alone separates two neighbouring probe nodes (a corner and the centre of one
    /// tile). Every tile point is within 0.65 half diagonals (2.24 cells) of a probe node, so a
    /// piece whose inside holds a ball of that radius, and whose outside does too, is found
    /// unless another piece lies within one probe spacing of it on that path; what can be lost is
    /// a small isolated bubble (under ~4.5 cells across) or a piece nested that close against
    /// another. The tiles the surface crosses are sampled as before, the ones beside it only
    /// probed.
    #[default]
    SignChange,
}

/// What the polygonizer did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PolygonizeStats {
    /// Cells in the whole grid (`nx · ny · nz`).
    pub cells_total: u64,
    /// Blocks the grid was split into.
    pub blocks_total: usize,
    /// Blocks sampled: those for which the field said the zero set may pass (the sparse narrow
    /// band), plus those the zero set was followed into from a sampled neighbour.
    pub blocks_active: usize,
    /// Field values evaluated (grid corners of the sampled tiles plus refinement steps; the normals' gradients are not counted).
    pub field_evaluations: u64,
}

/// Why polygonization failed.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum PolygonizeError {
    /// `resolution` was 0.
    #[error("the polygonization resolution must be at least 1 (cells along the longest axis)")]
    ZeroResolution,
    /// The domain box is empty, flat in every direction, or not finite.
    #[error(
        "the polygonization domain {min:?}..{max:?} is empty or not finite; give a box with a positive extent"
    )]
    EmptyDomain {
        /// Lower corner of the domain as given.
        min: [f64; 3],
        /// Upper corner of the domain as given.
        max: [f64; 3],
    },
    /// The grid would have more cells than allowed.
    #[error(
        "the polygonization grid would have {cells} cells, more than the limit {limit}; lower the resolution"
    )]
    GridTooLarge {
        /// Cells the grid would have (saturated at `u64::MAX`).
        cells: u64,
        /// The `max_cells` limit.
        limit: u64,
    },
    /// The mesh would have more vertices than 32-bit indices can address.
    #[error(
        "the mesh would have {vertices} vertices, more than 32-bit indices allow; lower the resolution"
    )]
    TooManyVertices {
        /// Number of vertices found.
        vertices: usize,
    },
    /// The caller cancelled through [`crate::progress::Progress::cancelled`].
    #[error("polygonization was cancelled")]
    Cancelled,
}
