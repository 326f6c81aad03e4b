//! Surface-independent fitting: collocation matrix, methods, budgets.

pub mod bezier_rows;
pub mod budget;
pub mod distance;
pub mod engine;
pub mod normal_matrix;
pub mod normal_solve;
pub mod sparse;
pub mod stencil_matrix;

pub use budget::{Budget, FitStatus, StepStats};
pub use engine::{fit, FitError, FitOutcome, FitProblem, Method, StepHook};
pub use sparse::{Collocation, Csr};
