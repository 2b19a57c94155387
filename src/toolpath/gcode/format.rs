//! Fixed-point text of coordinates: never an exponent nor `-0`, as many decimals as the program uses.

use super::super::lexer::{Line, TokenKind, WordValue};

/// Fixed-point text of a coordinate: 4 decimals in mm, 5 in inches; never `-0` nor an exponent.
pub fn format_coord(v: f64, inches: bool) -> String {
    format_decimals(v, if inches { 5 } else { 4 })
}

/// Fixed-point text with `d` decimals; never `-0` nor an exponent.
pub fn format_decimals(v: f64, d: usize) -> String {
    // Fast path: the value in units of the last decimal fits an integer exactly.
    if let Some(units) = decimal_units(v, d) {
        return units_text(units, d);
    }
    format_decimals_slow(v, d)
}

/// `v` rounded to `d` decimals, in units of the last decimal, when that is exact in an f64.
pub(super) fn decimal_units(v: f64, d: usize) -> Option<i64> {
    const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
    let n = (v * *POW10.get(d)?).round();
    (n.is_finite() && n.abs() < 4e15).then_some(n as i64)
}

/// `units` × 10^-d as fixed-point text (`-0` written as `0`).
pub(super) fn units_text(units: i64, d: usize) -> String {
    let mut t = String::with_capacity(24);
    push_units(&mut t, units, d);
    t
}

/// Append `units` × 10^-d as fixed-point text (`-0` written as `0`), digit by digit.
pub(super) fn push_units(buf: &mut String, units: i64, d: usize) {
    // 20 digits hold any u64, a sign and a point make 22.
    let mut digits = [0u8; 24];
    let mut n = units.unsigned_abs();
    let mut i = digits.len();
    let mut written = 0;
    while n > 0 || written <= d {
        if written == d && d > 0 {
            i -= 1;
            digits[i] = b'.';
        }
        i -= 1;
        digits[i] = b'0' + (n % 10) as u8;
        n /= 10;
        written += 1;
    }
    if units < 0 {
        i -= 1;
        digits[i] = b'-';
    }
    buf.push_str(std::str::from_utf8(&digits[i..]).unwrap_or("0"));
}

pub(super) fn format_decimals_slow(v: f64, d: usize) -> String {
    let s = format!("{v:.d$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Most decimals written in an X/Y/Z/I/J/K/R number of the program, capped at 9.
pub(super) fn coordinate_decimals(text: &str, lines: &[Line]) -> usize {
    let mut most = 0;
    for line in lines {
        for t in &line.tokens {
            if let TokenKind::Word {
                letter: b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R',
                value: WordValue::Number(_),
            } = t.kind
            {
                let w = text.get(t.span.clone()).unwrap_or("");
                if let Some(dot) = w.find('.') {
                    let d = w[dot + 1..]
                        .chars()
                        .take_while(|c| c.is_ascii_digit())
                        .count();
                    most = most.max(d);
                }
            }
        }
    }
    most.min(9)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_written_as_fixed_point() {
        let t = |u: i64, d: usize| {
            let mut s = String::new();
            push_units(&mut s, u, d);
            s
        };
        assert_eq!(t(12345, 4), "1.2345");
        assert_eq!(t(5, 4), "0.0005");
        assert_eq!(t(-5, 4), "-0.0005");
        assert_eq!(t(0, 4), "0.0000");
        assert_eq!(t(0, 0), "0");
        assert_eq!(t(-120, 0), "-120");
        assert_eq!(t(-1_000_000_000, 9), "-1.000000000");
        assert_eq!(format_decimals(-0.00001, 4), "0.0000");
        assert_eq!(format_decimals(2.5e-5, 4), "0.0000");
        assert_eq!(format_decimals(-12.34565, 5), "-12.34565");
    }
}
