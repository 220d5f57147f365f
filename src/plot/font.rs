//! The one font every plot uses: DejaVu Sans, embedded in the binary (licence in
//! `assets/fonts/`), registered with plotters' pure-Rust `ab_glyph` text renderer. Embedding it
//! keeps plots free of fontconfig/freetype and makes them look the same on every machine.

use std::sync::Once;

use plotters::style::FontStyle;

/// The family name plots ask for.
pub(crate) const FAMILY: &str = "sans-serif";

static DEJAVU_SANS: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Registers the font (once per process).
pub(crate) fn register() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TrueType file checked in with the source; a failure here is a
        // broken build, which the plot tests catch.
        let registered = plotters::style::register_font(FAMILY, FontStyle::Normal, DEJAVU_SANS);
        debug_assert!(registered.is_ok(), "embedded DejaVu Sans does not parse");
    });
}
