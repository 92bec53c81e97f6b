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

#[cfg(test)]
mod tests {
    use super::{Named, UnknownName};
    use crate::volume::Repr;

    /// Every value of `T` is read back from its name and each of its aliases.
    fn round_trips<T: Named + std::fmt::Debug>() {
        for c in T::CHOICES {
            assert_eq!(T::from_name(c.name), Some(c.value), "{}", c.name);
            assert_eq!(c.value.name(), c.name);
            for alias in c.aliases {
                assert_eq!(T::from_name(alias), Some(c.value), "{alias}");
            }
        }
    }

    #[test]
    fn every_table_names_each_value_once() {
        round_trips::<crate::sweep::Sweep>();
        round_trips::<crate::volume::Space>();
        round_trips::<crate::volume::FilterArg>();
        round_trips::<Repr>();
        round_trips::<crate::volume::EstimatorArg>();
        round_trips::<crate::volume::VolumeBackend>();
        round_trips::<crate::volume::RawTypeArg>();
        round_trips::<crate::volume::EndianArg>();
        round_trips::<crate::render::run::RenderBackend>();
        round_trips::<crate::render::spec::View>();
        round_trips::<crate::render::spec::VolumeMode>();
        round_trips::<crate::render::detector::ColorBy>();
        round_trips::<crate::gpu::TexelStore>();
        round_trips::<crate::scan::Backend>();
        round_trips::<crate::scan::Precision>();
    }

    #[test]
    fn names_parse_display_and_others_are_refused_with_the_list() {
        assert_eq!("bc4".parse::<Repr>(), Ok(Repr::Bc4));
        assert_eq!("source".parse::<Repr>(), Ok(Repr::Source));
        assert_eq!(Repr::Unorm16.to_string(), "unorm16");
        let e = "jpeg".parse::<Repr>().unwrap_err();
        assert_eq!(
            e,
            UnknownName {
                value: "jpeg".into(),
                names: vec!["nanovdb", "source", "bc4", "unorm8", "unorm16", "f16", "f32"],
            }
        );
        assert_eq!(
            e.to_string(),
            "invalid value 'jpeg' [possible values: nanovdb, source, bc4, unorm8, unorm16, f16, f32]"
        );
        // Names are matched exactly, as the command line matches them.
        assert!("BC4".parse::<Repr>().is_err());
    }
}
