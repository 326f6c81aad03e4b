//! The error for a core enum's `FromStr`: the core names its choices (`name()`, `ALL`)
//! so that front ends (the CLI's value parsers, config files) need no derive of their own
//! in the core.

/// A name that matches none of an enum's names (the message lists the accepted ones).
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("unknown name {given:?}; expected one of: {}", expected.join(", "))]
pub struct UnknownName {
    /// What was given.
    pub given: String,
    /// The accepted names.
    pub expected: Vec<&'static str>,
}

impl UnknownName {
    pub(crate) fn new(given: &str, expected: impl IntoIterator<Item = &'static str>) -> Self {
        Self {
            given: given.to_string(),
            expected: expected.into_iter().collect(),
        }
    }
}
