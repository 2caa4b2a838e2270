//! Progress reporting and cancellation, shared by every long-running stage.
//!
//! The library never draws anything: it calls a [`Progress`] that the command line turns into a
//! progress bar and the server into job status / server-sent events.

use std::sync::atomic::{AtomicBool, Ordering};

/// A stage of a run, as reported to a [`Progress`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Reading the input.
    Read,
    /// Dropping non-finite points, merging duplicates, outliers, normalising.
    Clean,
    /// Estimating and orienting normals (inputs without them).
    Normals,
    /// Building the spatial index and choosing the support.
    Index,
    /// Fitting the carrier solid and the offsets.
    Carrier,
    /// Assembling the sparse matrix.
    Assemble,
    /// Ordering the matrix.
    Order,
    /// Factorising it.
    Factor,
    /// Solving for the coefficients.
    Solve,
    /// Fitting partition-of-unity blocks (spans assemble … solve once per block).
    Blocks,
    /// Extracting the mesh.
    Polygonize,
    /// Trimming, floaters, mesh optimisation and topology.
    Post,
    /// Writing the mesh and report.
    Write,
    /// Contouring a 2D curve (the `curve` workbench).
    Contour,
    /// Training the neural approximator (the `curve` workbench).
    Train,
}

/// The stages of a 3D reconstruction in order, with their share of the overall progress
/// (fixed estimates; they sum to 1). [`Stage::Blocks`] spans assemble … solve.
const RECONSTRUCTION: [(Stage, f64); 12] = [
    (Stage::Read, 0.02),
    (Stage::Clean, 0.02),
    (Stage::Index, 0.03),
    (Stage::Normals, 0.03),
    (Stage::Carrier, 0.03),
    (Stage::Assemble, 0.10),
    (Stage::Order, 0.05),
    (Stage::Factor, 0.22),
    (Stage::Solve, 0.05),
    (Stage::Polygonize, 0.35),
    (Stage::Post, 0.05),
    (Stage::Write, 0.05),
];

impl Stage {
    /// Lower-case name, as shown in progress bars, job status and the report.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Read => "read",
            Stage::Clean => "clean",
            Stage::Normals => "normals",
            Stage::Index => "index",
            Stage::Carrier => "carrier",
            Stage::Assemble => "assemble",
            Stage::Order => "order",
            Stage::Factor => "factor",
            Stage::Solve => "solve",
            Stage::Blocks => "blocks",
            Stage::Polygonize => "polygonize",
            Stage::Post => "post",
            Stage::Write => "write",
            Stage::Contour => "contour",
            Stage::Train => "train",
        }
    }

    /// Where this stage lies in the overall progress of a reconstruction: `(start, end)` in
    /// `0..=1`; `None` for the 2D workbench's stages.
    pub fn span(self) -> Option<(f64, f64)> {
        if self == Stage::Blocks {
            return Some((Stage::Assemble.span()?.0, Stage::Solve.span()?.1));
        }
        let i = RECONSTRUCTION.iter().position(|(s, _)| *s == self)?;
        let start: f64 = RECONSTRUCTION[..i].iter().map(|(_, w)| w).sum();
        Some((start, start + RECONSTRUCTION[i].1))
    }

    /// Overall progress of a reconstruction at `fraction` of this stage.
    pub fn overall(self, fraction: f64) -> Option<f64> {
        let (a, b) = self.span()?;
        Some(a + (b - a) * fraction.clamp(0.0, 1.0))
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Receives stage changes and progress fractions; answers whether the work should stop.
/// Implementations must be cheap: stages call [`Progress::fraction`] up to a few thousand times.
pub trait Progress: Sync {
    /// A new stage starts.
    fn stage(&self, stage: Stage);
    /// Fraction `0.0..=1.0` of the current stage done.
    fn fraction(&self, done: f64);
    /// True when the caller asked to stop; stages return their `Cancelled` error soon after.
    fn cancelled(&self) -> bool;
}

/// A [`Progress`] that reports nothing and is never cancelled.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _stage: Stage) {}
    fn fraction(&self, _done: f64) {}
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that reports nothing and can be cancelled through a flag (used by tests and the server).
#[derive(Debug, Default)]
pub struct CancelFlag(pub AtomicBool);

impl CancelFlag {
    /// Ask the work to stop.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

impl Progress for CancelFlag {
    fn stage(&self, _stage: Stage) {}
    fn fraction(&self, _done: f64) {}
    fn cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_weights_sum_to_one_and_progress_is_monotone() {
        let total: f64 = RECONSTRUCTION.iter().map(|(_, w)| w).sum();
        assert!((total - 1.0).abs() < 1e-12);
        let mut last = 0.0;
        for (s, _) in RECONSTRUCTION {
            for f in [0.0, 0.5, 1.0] {
                let p = s.overall(f).unwrap();
                assert!(p >= last - 1e-12, "{s} {f}");
                last = p;
            }
        }
        assert!((last - 1.0).abs() < 1e-12);
        assert_eq!(Stage::Contour.overall(0.5), None);
        let (a, b) = Stage::Blocks.span().unwrap();
        assert_eq!(
            (a, b),
            (
                Stage::Assemble.span().unwrap().0,
                Stage::Solve.span().unwrap().1
            )
        );
    }
}
