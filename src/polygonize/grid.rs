//! The uniform grid of cubic cells over the domain, its split into blocks, and global corner / edge ids.
//!
//! Corner `(i, j, k)` sits at `origin + (i, j, k) · h`, always computed by the same expression so that
//! neighbouring blocks see bit-identical positions. Every edge used by the Kuhn triangulation joins a
//! corner `c` to `c + d` with `d ∈ {0,1}³ \ {0}`, so `corner_id(c) · 7 + (d − 1)` is a unique global
//! edge id (the key that welds vertices shared by cells and blocks).

use super::params::{PolygonizeError, PolygonizeParams};
use crate::geometry::{Aabb, Point3};

/// Cells along each axis of a block (the unit of work and of the narrow-band test).
pub(crate) const BLOCK: usize = 16;

/// The grid: origin, cell edge, cell counts and block counts.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Grid {
    /// Position of corner `(0, 0, 0)`.
    pub origin: Point3,
    /// Cell edge length.
    pub h: f64,
    /// Cells along x, y, z.
    pub cells: [usize; 3],
    /// Blocks along x, y, z.
    pub blocks: [usize; 3],
}

impl Grid {
    /// Covers `domain` with cubic cells (`resolution` along its longest axis), centred on the domain.
    /// Checks the cell count against `max_cells` before anything is allocated.
    pub(crate) fn new(domain: &Aabb, params: &PolygonizeParams) -> Result<Grid, PolygonizeError> {
        if params.resolution == 0 {
            return Err(PolygonizeError::ZeroResolution);
        }
        let ext = domain.extent();
        let longest = ext.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let finite = domain.min.iter().chain(&domain.max).all(|x| x.is_finite());
        if domain.is_empty() || !finite || ext.iter().any(|&e| e < 0.0) || longest <= 0.0 {
            return Err(PolygonizeError::EmptyDomain {
                min: domain.min,
                max: domain.max,
            });
        }
        let h = longest / params.resolution as f64;
        let mut cells = [0usize; 3];
        let mut total: u128 = 1;
        let mut corners: u128 = 1;
        for k in 0..3 {
            let n = ((ext[k] / h) * (1.0 - 1e-12)).ceil().max(1.0);
            // Saturating float → int conversion; a huge count is rejected just below.
            cells[k] = n.min(u32::MAX as f64 * 4.0) as usize;
            total = total.saturating_mul(cells[k] as u128);
            corners = corners.saturating_mul(cells[k] as u128 + 1);
        }
        if total > params.max_cells as u128 || corners.saturating_mul(7) > u64::MAX as u128 {
            return Err(PolygonizeError::GridTooLarge {
                cells: total.min(u64::MAX as u128) as u64,
                limit: params.max_cells,
            });
        }
        let center = domain.center();
        let origin = [0, 1, 2].map(|k| center[k] - 0.5 * cells[k] as f64 * h);
        let blocks = cells.map(|n| n.div_ceil(BLOCK));
        Ok(Grid {
            origin,
            h,
            cells,
            blocks,
        })
    }

    /// Total number of cells.
    pub(crate) fn cell_count(&self) -> u64 {
        self.cells.iter().map(|&n| n as u64).product()
    }

    /// Total number of blocks.
    pub(crate) fn block_count(&self) -> usize {
        self.blocks.iter().product()
    }

    /// Position of grid corner `c`.
    #[inline]
    pub(crate) fn corner(&self, c: [usize; 3]) -> Point3 {
        [0, 1, 2].map(|k| self.origin[k] + c[k] as f64 * self.h)
    }

    /// Global id of corner `c` (row-major over the `(n + 1)³` corners).
    #[inline]
    pub(crate) fn corner_id(&self, c: [usize; 3]) -> u64 {
        let (nx, ny) = (self.cells[0] as u64 + 1, self.cells[1] as u64 + 1);
        c[0] as u64 + nx * (c[1] as u64 + ny * c[2] as u64)
    }

    /// Cell range `[lo, hi)` of block number `b` (x fastest).
    pub(crate) fn block_cells(&self, b: usize) -> ([usize; 3], [usize; 3]) {
        let bi = [
            b % self.blocks[0],
            (b / self.blocks[0]) % self.blocks[1],
            b / (self.blocks[0] * self.blocks[1]),
        ];
        let lo = bi.map(|i| i * BLOCK);
        let hi = [0, 1, 2].map(|k| (lo[k] + BLOCK).min(self.cells[k]));
        (lo, hi)
    }

    /// The block holding global tile `g` (global cell / [`super::block::TILE`] per axis) and the
    /// tile's local index in it (x fastest).
    pub(crate) fn tile_home(&self, g: [usize; 3]) -> (usize, usize) {
        let per = BLOCK / super::block::TILE;
        let bi = g.map(|x| x / per);
        let b = bi[0] + self.blocks[0] * (bi[1] + self.blocks[1] * bi[2]);
        let (lo, hi) = self.block_cells(b);
        let tiles = super::block::tile_counts([0, 1, 2].map(|k| hi[k] - lo[k] + 1));
        let l = g.map(|x| x % per);
        (b, l[0] + tiles[0] * (l[1] + tiles[1] * l[2]))
    }

    /// Closed box of block `b` (its corner positions, as computed for the samples).
    pub(crate) fn block_box(&self, b: usize) -> Aabb {
        let (lo, hi) = self.block_cells(b);
        Aabb {
            min: self.corner(lo),
            max: self.corner(hi),
        }
    }
}
