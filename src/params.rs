//! Reconstruction parameters: one definition shared by the library, the command line, the HTTP API
//! and the report. Defaults live only in [`ReconParams::default`].

use crate::geometry::clean::CleanParams;
use crate::linalg::SolverKind;
use crate::ordering::OrderingKind;
use crate::rbf::{CarrierParams, Kernel, Support};
use crate::spatial::IndexKind;

/// Optional polynomial part of the spline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Polynomial {
    /// No polynomial: `A λ = r` (symmetric positive definite).
    #[default]
    None,
    /// `p = v₀ + v·x`: the doubly bordered system, solved block-wise (George & Liu).
    Linear,
}

impl std::str::FromStr for Polynomial {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => Ok(Polynomial::None),
            "linear" => Ok(Polynomial::Linear),
            _ => Err(format!("unknown polynomial '{s}' (use none or linear)")),
        }
    }
}

impl std::fmt::Display for Polynomial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Polynomial::None => "none",
            Polynomial::Linear => "linear",
        })
    }
}

/// Everything that steers a reconstruction.
#[derive(Debug, Clone, PartialEq)]
pub struct ReconParams {
    /// Wendland kernel (default `wendland-c2`).
    pub kernel: Kernel,
    /// Support radius or target neighbour count (default 30 neighbours).
    pub support: Support,
    /// Carrier solid (default `auto`: local tangent planes with normals, else ellipsoid).
    pub carrier: CarrierParams,
    /// Spatial index for neighbour queries (default: the faster in the `spatial` bench).
    pub index: IndexKind,
    /// Octree leaf size K (seed Algorithm I), default 16.
    pub leaf_size: usize,
    /// Matrix ordering (default `rcm`; used by the envelope solver and reported for all).
    pub ordering: OrderingKind,
    /// Linear solver (default `sparse`: faer supernodal Cholesky with AMD).
    pub solver: SolverKind,
    /// Polynomial part (default none).
    pub polynomial: Polynomial,
    /// Marching grid cells along the longest axis; `None` chooses from the point spacing (64–400).
    pub resolution: Option<usize>,
    /// Input cleaning.
    pub clean: CleanParams,
    /// Memory budget for the matrix and its factor, MiB (default 8192). Bigger systems are refused
    /// before allocation, with an estimate.
    pub max_memory_mib: u64,
}

impl Default for ReconParams {
    fn default() -> Self {
        ReconParams {
            kernel: Kernel::default(),
            support: Support::default(),
            carrier: CarrierParams::default(),
            index: IndexKind::default(),
            leaf_size: 16,
            ordering: OrderingKind::Rcm,
            solver: SolverKind::Sparse,
            polynomial: Polynomial::None,
            resolution: None,
            clean: CleanParams::default(),
            max_memory_mib: 8192,
        }
    }
}

/// A parameter outside its valid range.
#[derive(Debug, thiserror::Error)]
#[error("invalid parameter {name} = {value}: {expected}")]
pub struct ParamError {
    /// Parameter name as on the command line (`support`, `neighbours`, ...).
    pub name: &'static str,
    /// The offending value.
    pub value: String,
    /// What is allowed.
    pub expected: &'static str,
}

impl ReconParams {
    /// Check ranges; the command line and the HTTP API call this before any work.
    pub fn validate(&self) -> Result<(), ParamError> {
        let err = |name, value: String, expected| {
            Err(ParamError {
                name,
                value,
                expected,
            })
        };
        match self.support {
            Support::Radius(r) if !(r.is_finite() && r > 0.0 && r <= 2.0) => {
                return err(
                    "support",
                    r.to_string(),
                    "a radius in (0, 2] normalised units (the longest bbox edge is 1)",
                );
            }
            Support::Neighbours(k) if !(4..=2000).contains(&k) => {
                return err("neighbours", k.to_string(), "an integer in 4..=2000");
            }
            _ => {}
        }
        if let Some(r) = self.resolution
            && !(8..=4096).contains(&r)
        {
            return err("resolution", r.to_string(), "an integer in 8..=4096");
        }
        if !(1..=4096).contains(&self.leaf_size) {
            return err(
                "leaf-size",
                self.leaf_size.to_string(),
                "an integer in 1..=4096",
            );
        }
        let tol = self.clean.merge_tolerance;
        if !(tol.is_finite() && (0.0..=1e-2).contains(&tol)) {
            return err(
                "merge-tolerance",
                tol.to_string(),
                "a fraction of the bbox diagonal in [0, 0.01]",
            );
        }
        if !(16..=1 << 22).contains(&self.max_memory_mib) {
            return err(
                "max-memory-mib",
                self.max_memory_mib.to_string(),
                "MiB in 16..=4194304",
            );
        }
        Ok(())
    }
}
