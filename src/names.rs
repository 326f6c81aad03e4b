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

#[cfg(test)]
mod tests {
    use crate::bspline::fit::GridMethod;
    use crate::fit::Method;
    use crate::io::iges::IgesUnits;
    use crate::mesh::inverse::InverseMethod;

    #[test]
    fn every_name_parses_back_to_its_value_and_an_unknown_one_lists_them() {
        for m in GridMethod::ALL {
            assert_eq!(m.name().parse::<GridMethod>(), Ok(m));
        }
        for u in IgesUnits::ALL {
            assert_eq!(u.to_string().parse::<IgesUnits>(), Ok(u));
        }
        for m in Method::ALL {
            assert_eq!(m.name().parse::<Method>(), Ok(m));
        }
        for m in InverseMethod::ALL {
            assert_eq!(m.name().parse::<InverseMethod>(), Ok(m));
        }
        let e = "cm".parse::<IgesUnits>().expect_err("not a unit");
        assert_eq!(
            e.to_string(),
            "unknown name \"cm\"; expected one of: mm, m, in"
        );
        // The names in output files are the serde names.
        assert_eq!(
            serde_json::to_value(GridMethod::TwoPass).expect("serialises"),
            GridMethod::TwoPass.name()
        );
        assert_eq!(
            serde_json::to_value(Method::Lspia).expect("serialises"),
            Method::Lspia.name()
        );
    }
}
