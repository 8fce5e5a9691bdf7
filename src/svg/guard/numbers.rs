//! Numbers in attribute and style text: finding them as SVG writes them, and their bound.

use super::{SvgLimits, SvgRejected};

pub(super) fn in_range(
    v: f64,
    limits: &SvgLimits,
    tag: &str,
    attr: &str,
) -> Result<(), SvgRejected> {
    if v.is_finite() && v.abs() <= limits.max_number {
        Ok(())
    } else {
        Err(SvgRejected::Number {
            tag: tag.to_string(),
            attr: attr.to_string(),
            value: v,
            max: limits.max_number,
        })
    }
}

/// Calls `f` on every number in `s`; returns how many there were. `path_like` (path data and
/// point lists) reads a letter before a digit as a command; elsewhere a digit glued to a name
/// (`cls1e5`, `#1e3838`) belongs to the name, and `url(…)` and quoted strings are skipped.
pub(super) fn scan_numbers(
    s: &str,
    path_like: bool,
    mut f: impl FnMut(f64) -> Result<(), SvgRejected>,
) -> Result<usize, SvgRejected> {
    let b = s.as_bytes();
    let name_char = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'-';
    let mut i = 0;
    let mut n = 0;
    while i < b.len() {
        let c = b[i];
        if !path_like {
            if b[i..].starts_with(b"url(") {
                i += b[i..]
                    .iter()
                    .position(|&x| x == b')')
                    .unwrap_or(b.len() - i);
                continue;
            }
            if c == b'"' || c == b'\'' {
                i += 1;
                i += b[i..]
                    .iter()
                    .position(|&x| x == c)
                    .map_or(b.len() - i, |p| p + 1);
                continue;
            }
            if c == b'#' || c.is_ascii_alphabetic() || c == b'_' {
                i += 1;
                while i < b.len() && name_char(b[i]) {
                    i += 1;
                }
                continue;
            }
        }
        let digit_at = |j: usize| b.get(j).is_some_and(u8::is_ascii_digit);
        let starts = c.is_ascii_digit()
            || (c == b'.' && digit_at(i + 1))
            || ((c == b'+' || c == b'-')
                && (digit_at(i + 1) || (b.get(i + 1) == Some(&b'.') && digit_at(i + 2))));
        if !starts {
            i += 1;
            continue;
        }
        let start = i;
        if c == b'+' || c == b'-' {
            i += 1;
        }
        while digit_at(i) {
            i += 1;
        }
        if b.get(i) == Some(&b'.') {
            i += 1;
            while digit_at(i) {
                i += 1;
            }
        }
        if matches!(b.get(i), Some(b'e' | b'E')) {
            let mut j = i + 1;
            if matches!(b.get(j), Some(b'+' | b'-')) {
                j += 1;
            }
            if digit_at(j) {
                i = j;
                while digit_at(i) {
                    i += 1;
                }
            }
        }
        // The slice is ASCII digits, signs, '.', 'e': it always parses (overflow gives ±inf).
        let v = s[start..i].parse::<f64>().unwrap_or(f64::INFINITY);
        f(v)?;
        n += 1;
    }
    Ok(n)
}
