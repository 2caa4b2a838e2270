//! Progress reporting and cancellation, shared by every long-running stage.
//!
//! The library never draws anything: it calls a [`Progress`] that the command line turns into a
//! progress bar and the server into job status / server-sent events.

use std::sync::atomic::{AtomicBool, Ordering};

/// Receives stage changes and progress fractions; answers whether the work should stop.
/// Implementations must be cheap: stages call [`Progress::fraction`] up to a few thousand times.
pub trait Progress: Sync {
    /// A new stage starts (`"read"`, `"index"`, `"assemble"`, `"factor"`, `"polygonize"`, ...).
    fn stage(&self, name: &str);
    /// Fraction `0.0..=1.0` of the current stage done.
    fn fraction(&self, done: f64);
    /// True when the caller asked to stop; stages return their `Cancelled` error soon after.
    fn cancelled(&self) -> bool;
}

/// A [`Progress`] that reports nothing and is never cancelled.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _name: &str) {}
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
    fn stage(&self, _name: &str) {}
    fn fraction(&self, _done: f64) {}
    fn cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}
