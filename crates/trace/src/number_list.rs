//! Comma-separated lists of numbers, as command-line options (`--dims 64,64,32`) and photon
//! source specifications (`point:0,0,5`) write them.

/// What is wrong with a list of numbers; callers say which option or specification it is.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum NumberListError {
    /// The list has another number of items.
    #[error("{got} items, expected {expected}")]
    Count {
        /// Items in the list.
        got: usize,
        /// Items expected.
        expected: usize,
    },
    /// An item is not a finite number.
    #[error("`{0}` is not a finite number")]
    NotFinite(String),
}

/// The `N` finite numbers of `text`, separated by commas (spaces around each allowed).
pub fn parse_numbers<const N: usize>(text: &str) -> Result<[f64; N], NumberListError> {
    let items: Vec<&str> = text.split(',').map(str::trim).collect();
    if items.len() != N {
        return Err(NumberListError::Count {
            got: items.len(),
            expected: N,
        });
    }
    let mut out = [0.0; N];
    for (o, item) in out.iter_mut().zip(&items) {
        *o = item
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| NumberListError::NotFinite(item.to_string()))?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_of_finite_numbers_parse_and_others_are_refused() {
        assert_eq!(parse_numbers::<3>(" 1, -2.5 ,3e2"), Ok([1.0, -2.5, 300.0]));
        assert_eq!(
            parse_numbers::<2>("1,2,3"),
            Err(NumberListError::Count {
                got: 3,
                expected: 2
            })
        );
        assert_eq!(
            parse_numbers::<2>("1,inf"),
            Err(NumberListError::NotFinite("inf".into()))
        );
        assert_eq!(
            parse_numbers::<1>("x"),
            Err(NumberListError::NotFinite("x".into()))
        );
        assert!(parse_numbers::<1>("").is_err());
    }
}
