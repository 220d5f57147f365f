//! What `hybc` prints, split into numbers and the text between them, so that the tests that pin
//! printed output (the tutorial, the CLI cases) compare numbers within a relative tolerance and
//! everything else exactly.

/// A piece of printed output.
#[derive(Debug, Clone, PartialEq)]
pub enum Token {
    /// Text between numbers, including names whose digits are part of the name (`h0`, `dt1`).
    Text(String),
    /// A number as printed, and its value.
    Number(String, f64),
}

/// `text` as numbers and the text between them. A number starts at a digit, or at a `-` right
/// before one, outside a name (`h0` and `x_2` are names); it runs over digits and dots, with an
/// exponent (`e`, an optional sign, digits). A dot that ends a sentence (`... at t = 4.06.`) is
/// not part of the number; a run of digits and dots that is no number (`0.1.0`) stays text.
pub fn tokens(text: &str) -> Vec<Token> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut text_start = 0;
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_alphabetic() || c == b'_' {
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            continue;
        }
        let starts_number = c.is_ascii_digit() || (c == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        if !starts_number {
            i += 1;
            continue;
        }
        let start = i;
        i += 1;
        while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
            i += 1;
        }
        // An exponent: e, an optional sign, digits.
        if i + 1 < b.len() && (b[i] == b'e' || b[i] == b'E') {
            let mut j = i + 1;
            if b[j] == b'-' || b[j] == b'+' {
                j += 1;
            }
            if j < b.len() && b[j].is_ascii_digit() {
                i = j;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
            }
        }
        let token = text[start..i].trim_end_matches('.');
        let Ok(value) = token.parse::<f64>() else { continue };
        if text_start < start {
            out.push(Token::Text(text[text_start..start].to_string()));
        }
        out.push(Token::Number(token.to_string(), value));
        text_start = start + token.len();
        i = text_start;
    }
    if text_start < b.len() {
        out.push(Token::Text(text[text_start..].to_string()));
    }
    out
}

/// The numbers in `text`, in order (see [`tokens`]).
pub fn numbers(text: &str) -> Vec<f64> {
    tokens(text)
        .into_iter()
        .filter_map(|t| match t {
            Token::Number(_, v) => Some(v),
            Token::Text(_) => None,
        })
        .collect()
}

/// Whether two printed numbers agree within the relative tolerance `rel`.
pub fn close(want: f64, got: f64, rel: f64) -> bool {
    want == got || (want - got).abs() <= rel * want.abs().max(got.abs())
}
