//! Surface-independent fitting: collocation matrix, methods, budgets.
#![warn(missing_docs)]

pub mod bezier_rows;
pub mod budget;
pub mod collocation;
pub mod csr;
pub mod distance;
pub mod engine;
pub(crate) mod normal_matrix;
pub(crate) mod normal_solve;
mod simd;
pub(crate) mod stencil_matrix;

pub use budget::{Budget, FitStatus, StepStats};
pub use collocation::Collocation;
pub use csr::Csr;
pub use engine::{fit, FitError, FitOutcome, FitProblem, Method, StepHook};
