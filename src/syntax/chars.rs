//! Characters a terminal would not show as themselves, and how the parser's messages and the
//! rendered diagnostics (`diag`) show them instead: one definition for both, here at the bottom,
//! so that `syntax` needs nothing of `diag` (which renders `syntax`'s spans).

/// Characters a terminal would not show as themselves: control characters other than tab and
/// line feed, zero-width and format characters, bidirectional overrides (which can make a line
/// read differently from what it contains), and combining marks ([`is_combining`]).
pub fn is_invisible(c: char) -> bool {
    (c.is_control() && c != '\n' && c != '\t')
        || matches!(c, '\u{00AD}' | '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2060}'..='\u{2064}' | '\u{2066}'..='\u{2069}' | '\u{FEFF}')
        || is_combining(c)
}

/// Combining marks that draw onto the character before them, so that `e` followed by U+0301 shows
/// as `é` and a caret under the mark points at nothing: the script-independent combining blocks
/// (general categories Mn and Me) and the variation selectors. Script-specific marks (Hebrew
/// points, Arabic vowels, Indic vowel signs) are left as they are: identifiers are ASCII, so such
/// marks occur only in comments, after letters of their script, where escaping them would make
/// the text unreadable. Ranges rather than a Unicode-table crate: these blocks are all that a
/// diagnostic needs.
pub fn is_combining(c: char) -> bool {
    matches!(c,
        '\u{0300}'..='\u{036F}'       // Combining Diacritical Marks (U+0301 acute, U+034F joiner)
        | '\u{0483}'..='\u{0489}'     // Cyrillic combining marks, U+0488..U+0489 enclosing (Me)
        | '\u{1AB0}'..='\u{1AFF}'     // Combining Diacritical Marks Extended
        | '\u{1DC0}'..='\u{1DFF}'     // Combining Diacritical Marks Supplement
        | '\u{20D0}'..='\u{20FF}'     // Combining Marks for Symbols (enclosing circle U+20DD, Me)
        | '\u{3099}'..='\u{309A}'     // combining kana voiced marks
        | '\u{A670}'..='\u{A672}'     // Cyrillic combining enclosing signs (Me)
        | '\u{FE00}'..='\u{FE0F}'     // Variation Selectors
        | '\u{FE20}'..='\u{FE2F}'     // Combining Half Marks
        | '\u{E0100}'..='\u{E01EF}' // Variation Selectors Supplement
    )
}

/// `<U+XXXX>`, how diagnostics show an invisible character.
pub fn escaped(c: char) -> String {
    format!("<U+{:04X}>", c as u32)
}
