//! Values chosen by name: command-line options and the Python package's keyword arguments
//! read an enum's values by the names of one table per enum ([`Named::CHOICES`]), which
//! also gives each its `FromStr` and `Display`.

/// One value of a [`Named`] enum: its name, the other names it is read from and a line of
/// help.
#[derive(Debug)]
pub struct Choice<T: 'static> {
    /// The value.
    pub value: T,
    /// Its name (what `Display` writes).
    pub name: &'static str,
    /// Other names it is read from.
    pub aliases: &'static [&'static str],
    /// What it means, in one line.
    pub help: &'static str,
}

/// An enum whose values are chosen by name.
pub trait Named: Copy + PartialEq + Sized + 'static {
    /// Every value, in the order they are listed.
    const CHOICES: &'static [Choice<Self>];

    /// The value of `text`, a name or an alias (exact match).
    fn from_name(text: &str) -> Option<Self> {
        Self::CHOICES
            .iter()
            .find(|c| c.name == text || c.aliases.contains(&text))
            .map(|c| c.value)
    }

    /// The name of this value.
    fn name(self) -> &'static str {
        Self::CHOICES
            .iter()
            .find(|c| c.value == self)
            .map_or("", |c| c.name)
    }

    /// Every name, in the order they are listed.
    fn names() -> Vec<&'static str> {
        Self::CHOICES.iter().map(|c| c.name).collect()
    }
}

/// A name that is not one of an enum's.
#[derive(Debug, PartialEq, thiserror::Error)]
#[error("invalid value '{value}' [possible values: {}]", names.join(", "))]
pub struct UnknownName {
    /// The name given.
    pub value: String,
    /// The names accepted.
    pub names: Vec<&'static str>,
}

/// Implements [`Named`] for an enum with the table `(variant, name, [aliases], help)`,
/// and `FromStr` and `Display` with those names.
macro_rules! named {
    ($ty:ty { $(($value:expr, $name:literal, [$($alias:literal),*], $help:literal)),+ $(,)? }) => {
        impl $crate::choice::Named for $ty {
            const CHOICES: &'static [$crate::choice::Choice<Self>] = &[$(
                $crate::choice::Choice {
                    value: $value,
                    name: $name,
                    aliases: &[$($alias),*],
                    help: $help,
                }
            ),+];
        }

        impl std::str::FromStr for $ty {
            type Err = $crate::choice::UnknownName;

            fn from_str(text: &str) -> Result<Self, Self::Err> {
                <Self as $crate::choice::Named>::from_name(text).ok_or_else(|| {
                    $crate::choice::UnknownName {
                        value: text.to_string(),
                        names: <Self as $crate::choice::Named>::names(),
                    }
                })
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str($crate::choice::Named::name(*self))
            }
        }
    };
}

pub(crate) use named;
