//! The pure worker: (mesh, previous fit, config) -> fit.
