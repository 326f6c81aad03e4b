//! Surface-independent fitting: collocation matrix, methods, budgets.

pub mod bezier_rows;
pub mod budget;
pub mod collocation;
pub mod csr;
pub mod distance;
pub mod engine;
pub mod normal_matrix;
pub mod normal_solve;
mod simd;
pub mod stencil_matrix;

pub use budget::{Budget, FitStatus, StepStats};
pub use collocation::Collocation;
pub use csr::Csr;
pub use engine::{fit, FitError, FitOutcome, FitProblem, Method, StepHook};
