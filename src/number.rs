//! Numbers as hybc reads them from text (model literals, `--set`, `--vary`, `--target`): a
//! decimal that a double represents. `f64::from_str` rounds `1e-400` to 0 and `1e400` to infinity
//! without a word; here both are errors, so a value the user wrote never silently becomes another
//! one. A subnormal (`1e-310`) is accepted: it is a double, with fewer digits. No spans and no IO:
//! callers name the flag or point at the literal.

/// Why a text is not a number hybc accepts.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NumberError {
    /// Not a number at all.
    #[error("`{text}` is not a number")]
    NotANumber {
        /// The text as written.
        text: String,
    },
    /// `inf`, `nan` and their spellings.
    #[error("`{text}` is not a finite number")]
    NotFinite {
        /// The text as written.
        text: String,
    },
    /// Beyond the largest double.
    #[error("`{text}` is too large for a double (the largest is 1.7976931348623157e308)")]
    TooLarge {
        /// The text as written.
        text: String,
    },
    #[error(
        "`{text}` is too small for a double: it would round to 0 (the smallest positive double is \
         about 4.9e-324); write 0 if 0 is meant"
    )]
    /// Below the smallest positive double: it would round to 0.
    TooSmall {
        /// The text as written.
        text: String,
    },
}

/// Parses a finite decimal number (Rust's syntax: `1`, `-2.5`, `.5`, `3e-7`), refusing one a
/// double cannot hold: beyond the largest double, or nonzero but rounding to 0.
pub fn parse_number(text: &str) -> Result<f64, NumberError> {
    let owned = || text.to_string();
    let value: f64 = text.parse().map_err(|_| NumberError::NotANumber { text: owned() })?;
    let unsigned = text.trim_start_matches(['+', '-']);
    let decimal = unsigned.starts_with(|c: char| c.is_ascii_digit() || c == '.');
    if !value.is_finite() {
        return Err(if decimal {
            NumberError::TooLarge { text: owned() }
        } else {
            NumberError::NotFinite { text: owned() }
        });
    }
    // Zero from nonzero digits: the exponent took the value below the smallest subnormal.
    let mantissa = unsigned.split(['e', 'E']).next().unwrap_or("");
    if value == 0.0 && mantissa.bytes().any(|b| (b'1'..=b'9').contains(&b)) {
        return Err(NumberError::TooSmall { text: owned() });
    }
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn representable_decimals_parse_and_the_others_say_why_not() {
        for (text, value) in
            [("0", 0.0), ("-0.0", 0.0), ("1e-310", 1e-310), ("0e-999", 0.0), (".5", 0.5), ("1e308", 1e308)]
        {
            assert_eq!(parse_number(text), Ok(value), "{text}");
        }
        for text in ["1e-400", "-2e-324", "0.0001e-330"] {
            assert_eq!(parse_number(text), Err(NumberError::TooSmall { text: text.into() }), "{text}");
        }
        assert_eq!(parse_number("1e400"), Err(NumberError::TooLarge { text: "1e400".into() }));
        assert_eq!(parse_number("-inf"), Err(NumberError::NotFinite { text: "-inf".into() }));
        assert_eq!(parse_number("NaN"), Err(NumberError::NotFinite { text: "NaN".into() }));
        assert_eq!(parse_number("1,5"), Err(NumberError::NotANumber { text: "1,5".into() }));
    }
}
