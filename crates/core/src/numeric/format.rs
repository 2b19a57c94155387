//! Numbers as written to files: fixed-point text that is never `-0` nor an exponent (an exact formatter and a fast one for hot loops), and optional values.

use std::io::Write;

/// Fixed-point text with `digits` decimals and no "-0.000", rounded exactly as `format!`
/// rounds the binary value (controller tables, reports).
pub fn fixed(v: f64, digits: usize) -> String {
    let text = format!("{v:.digits$}");
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        text.trim_start_matches('-').to_string()
    } else {
        text
    }
}

/// An optional value with `digits` decimals, or `missing` (e.g. `n/a`, `–`) for none.
pub fn opt(v: Option<f64>, digits: usize, missing: &str) -> String {
    v.map_or_else(|| missing.to_string(), |v| format!("{v:.digits$}"))
}

/// Fixed-point text of a G-code coordinate: 4 decimals in mm, 5 in inches; never `-0` nor an
/// exponent.
pub fn format_coord(v: f64, inches: bool) -> String {
    format_decimals(v, if inches { 5 } else { 4 })
}

/// Fixed-point text with `d` decimals; never `-0` nor an exponent. Fast: the value is rounded
/// half away from zero in units of the last decimal (see [`decimal_units`]).
pub fn format_decimals(v: f64, d: usize) -> String {
    // Fast path: the value in units of the last decimal fits an integer exactly.
    if let Some(units) = decimal_units(v, d) {
        return units_text(units, d);
    }
    fixed(v, d)
}

/// `v` rounded to `d` decimals, in units of the last decimal, when that is exact in an f64.
pub fn decimal_units(v: f64, d: usize) -> Option<i64> {
    const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
    let n = (v * *POW10.get(d)?).round();
    (n.is_finite() && n.abs() < 4e15).then_some(n as i64)
}

/// `units` × 10^-d as fixed-point text (`-0` written as `0`).
pub fn units_text(units: i64, d: usize) -> String {
    let mut t = String::with_capacity(24);
    push_units(&mut t, units, d);
    t
}

/// Append `units` × 10^-d as fixed-point text (`-0` written as `0`), digit by digit.
#[inline]
pub fn push_units(buf: &mut String, units: i64, d: usize) {
    let mut digits = [0u8; UNITS_LEN];
    let start = units_digits(units, d, &mut digits);
    buf.push_str(std::str::from_utf8(&digits[start..]).unwrap_or("0"));
}

/// Bytes that hold `units_digits`' text: 20 digits hold any u64, a sign and a point make 22.
const UNITS_LEN: usize = 24;

/// Write `units` × 10^-d right-aligned into `digits`, returning where the text starts.
#[inline]
fn units_digits(units: i64, d: usize, digits: &mut [u8; UNITS_LEN]) -> usize {
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
    i
}

/// Bytes that hold any finite f64 at 4 decimals: sign, 309 integer digits, point, 4 decimals.
pub const FIXED4_BUF_LEN: usize = 320;

/// Write `value` rounded to 4 decimals (half away from zero) into `buf`, returning the used
/// bytes; never `-0`. For streams: no allocation. Values beyond ±9e14 fall back to `format!`.
#[inline]
pub fn format_fixed4(value: f64, buf: &mut [u8; FIXED4_BUF_LEN]) -> usize {
    let scaled = (value * 1e4).round();
    if scaled.is_nan() || scaled.abs() >= 9e18 {
        let mut cursor = std::io::Cursor::new(&mut buf[..]);
        let _ = write!(cursor, "{value:.4}");
        return cursor.position() as usize;
    }
    let mut digits = [0u8; UNITS_LEN];
    let start = units_digits(scaled as i64, 4, &mut digits);
    let len = UNITS_LEN - start;
    buf[..len].copy_from_slice(&digits[start..]);
    len
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
        assert_eq!(t(i64::MIN, 0), "-9223372036854775808");
        assert_eq!(format_decimals(-0.00001, 4), "0.0000");
        assert_eq!(format_decimals(2.5e-5, 4), "0.0000");
        assert_eq!(format_decimals(-12.34565, 5), "-12.34565");
        assert_eq!(format_coord(1.0 / 3.0, true), "0.33333");
        assert_eq!(format_decimals(1e300, 2), fixed(1e300, 2));
    }

    #[test]
    fn exact_formatter_drops_the_sign_of_zero_only() {
        assert_eq!(fixed(-0.00004, 4), "0.0000");
        assert_eq!(fixed(-0.00005001, 4), "-0.0001");
        assert_eq!(fixed(2.5, 0), "2"); // format! rounds the exact binary value half to even
        assert_eq!(opt(Some(-1.005), 1, "n/a"), "-1.0");
        assert_eq!(opt(None, 2, "–"), "–");
        assert_eq!(format!("{:>9}", opt(Some(12.3456), 3, "n/a")), "   12.346");
    }

    #[test]
    fn fixed4_matches_the_exact_formatter_away_from_ties() {
        let mut buf = [0u8; FIXED4_BUF_LEN];
        let mut f = |v: f64| {
            let n = format_fixed4(v, &mut buf);
            String::from_utf8(buf[..n].to_vec()).unwrap()
        };
        assert_eq!(f(-0.00004), "0.0000");
        assert_eq!(f(-0.0), "0.0000");
        assert_eq!(f(12.34567), "12.3457");
        assert_eq!(f(-7.0), "-7.0000");
        assert_eq!(f(123456789.0001), "123456789.0001");
        assert_eq!(f(1e300), format!("{:.4}", 1e300));
        assert_eq!(f(f64::NAN), "NaN");
        // Values whose 5th decimal is not a tie round as the exact formatter does.
        for k in 0..2000 {
            let v = (k as f64 - 1000.0) * 0.0123457 + 0.000011;
            let frac = (v * 1e4).abs().fract();
            if (frac - 0.5).abs() > 1e-6 {
                assert_eq!(f(v), fixed(v, 4), "{v}");
            }
        }
    }
}
