//! The command line's parser of [`Named`] values: the names of each enum's table, with
//! their help in `--help` and clap's message for a name that is not one of them.

use std::ffi::OsStr;
use std::marker::PhantomData;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use hytrace_trace::choice::Named;

/// Parses the names of `T`'s table ([`choice`]).
#[derive(Clone)]
pub struct ChoiceParser<T>(PhantomData<T>);

/// The value parser of an option taking one of `T`'s names.
pub fn choice<T>() -> ChoiceParser<T> {
    ChoiceParser(PhantomData)
}

impl<T: Named + Send + Sync> ChoiceParser<T> {
    fn values() -> impl Iterator<Item = PossibleValue> {
        T::CHOICES.iter().map(|c| {
            PossibleValue::new(c.name)
                .aliases(c.aliases.iter().copied())
                .help(c.help)
        })
    }
}

impl<T: Named + Send + Sync> TypedValueParser for ChoiceParser<T> {
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<T, clap::Error> {
        // clap's own parser of possible values gives its usual error for other names.
        let name = PossibleValuesParser::new(Self::values()).parse_ref(cmd, arg, value)?;
        Ok(T::from_name(&name).expect("a possible value is a name of the table"))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(Self::values()))
    }
}
