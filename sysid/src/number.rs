//! How sysid writes numbers into the files a user owns (URDF updates, noise tags, reports):
//! 7 significant digits, the shorter of plain and scientific form.

/// Formats a number with 7 significant digits, shortest form.
pub fn format_number(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let rounded: f64 = format!("{x:.6e}").parse().unwrap_or(x);
    let plain = format!("{rounded}");
    let sci = format!("{rounded:e}");
    if plain.len() <= sci.len() { plain } else { sci }
}
