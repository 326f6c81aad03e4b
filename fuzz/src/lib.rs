//! Fuzz targets of trispline's readers (see the README's fuzzing section).

pub mod targets;
