//! Range checks of option values: the one place that says what a "positive", a "non-negative"
//! and a "fraction" option value is (a finite number above, or at least, 0; one in [0, 1]) and
//! how a value out of range is reported, so that every options struct's `validate` reports it
//! alike.
//!
//! An options struct lists its keys with their values (an `Option<f64>` for a key that may be
//! absent: absent passes); each check returns `Err((key, message))` for the first value out of
//! range, which the struct's caller turns into an error naming the file and the key.

/// The key out of range and what is wrong with its value.
pub type Invalid = (&'static str, String);

/// Each value given is a positive, finite number.
///
/// # Errors
/// `(key, "must be a positive number (got …)")` for the first that is not.
pub fn positive<V: Into<Option<f64>>>(values: impl IntoIterator<Item = (&'static str, V)>) -> Result<(), Invalid> {
    first_outside(values, |v| v > 0.0, "a positive number")
}

/// Each value given is a finite number ≥ 0.
///
/// # Errors
/// `(key, "must be a non-negative number (got …)")` for the first that is not.
pub fn non_negative<V: Into<Option<f64>>>(values: impl IntoIterator<Item = (&'static str, V)>) -> Result<(), Invalid> {
    first_outside(values, |v| v >= 0.0, "a non-negative number")
}

/// Each value given is a number in [0, 1] (a gain or a share of a whole).
///
/// # Errors
/// `(key, "must be in [0, 1] (got …)")` for the first that is not.
pub fn fraction<V: Into<Option<f64>>>(values: impl IntoIterator<Item = (&'static str, V)>) -> Result<(), Invalid> {
    first_outside(values, |v| (0.0..=1.0).contains(&v), "in [0, 1]")
}

fn first_outside<V: Into<Option<f64>>>(
    values: impl IntoIterator<Item = (&'static str, V)>,
    within: impl Fn(f64) -> bool,
    what: &str,
) -> Result<(), Invalid> {
    for (key, v) in values {
        if let Some(v) = v.into()
            && !(within(v) && v.is_finite())
        {
            return Err((key, format!("must be {what} (got {v})")));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_value_out_of_range_is_named_and_absent_ones_pass() {
        assert_eq!(positive([("a", 1.0), ("b", 0.5)]), Ok(()));
        assert_eq!(
            positive([("a", Some(1.0)), ("b", None), ("c", Some(0.0)), ("d", Some(-1.0))]),
            Err(("c", "must be a positive number (got 0)".to_string()))
        );
        assert_eq!(positive([("a", f64::INFINITY)]), Err(("a", "must be a positive number (got inf)".to_string())));
        assert_eq!(
            non_negative([("a", 0.0), ("b", f64::NAN)]),
            Err(("b", "must be a non-negative number (got NaN)".to_string()))
        );
        assert_eq!(
            non_negative([("a", Some(-0.5))]),
            Err(("a", "must be a non-negative number (got -0.5)".to_string()))
        );
        assert_eq!(fraction([("a", 0.0), ("b", 1.0)]), Ok(()));
        assert_eq!(fraction([("a", 0.5), ("b", 1.5)]), Err(("b", "must be in [0, 1] (got 1.5)".to_string())));
        assert_eq!(fraction([("a", f64::NAN)]), Err(("a", "must be in [0, 1] (got NaN)".to_string())));
    }
}
