//! Enums that configs and the command line spell by fixed names. The names live here, in
//! the core (`FromStr`, `Display`, `NAMES`); the CLI builds its value parsers from them, so
//! the core needs no command-line library.

/// A name that is not one of an enum's values.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown value {given:?} (expected one of: {})", expected.join(", "))]
pub struct UnknownName {
    /// What was given.
    pub given: String,
    /// The accepted names.
    pub expected: &'static [&'static str],
}

/// `named!(Type { Variant => "name", ... })`: `Type::NAMES`, `Type::name`, `FromStr` and
/// `Display` over those names.
macro_rules! named {
    ($ty:ident { $($variant:ident => $name:literal),+ $(,)? }) => {
        impl $ty {
            /// Every value's name, in the order `--help` lists them.
            pub const NAMES: &'static [&'static str] = &[$($name),+];

            /// The name in configs and on the command line.
            pub fn name(self) -> &'static str {
                match self {
                    $($ty::$variant => $name),+
                }
            }
        }

        impl std::str::FromStr for $ty {
            type Err = $crate::pipeline::UnknownName;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                match s {
                    $($name => Ok($ty::$variant),)+
                    _ => Err($crate::pipeline::UnknownName {
                        given: s.to_string(),
                        expected: Self::NAMES,
                    }),
                }
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

pub(crate) use named;
