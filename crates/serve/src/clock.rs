//! UTC time stamps as the live contract spells them (RFC 3339, millisecond precision, `Z`), and the reading of the time ranges a history request names.

/// Milliseconds since 1970-01-01T00:00:00Z now.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
}

/// `YYYY-MM-DDThh:mm:ss.mmmZ` of a time in ms since the epoch.
pub fn utc_ms(ms: i64) -> String {
    errmap_core::io::stamp::utc_rfc3339_ms(ms)
}

/// Now as `YYYY-MM-DDThh:mm:ss.mmmZ`.
pub fn utc_now_ms() -> String {
    utc_ms(now_ms())
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Hinnant's `days_from_civil`).
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// A UTC time written `YYYY-MM-DDThh:mm[:ss[.fff]][Z]` (what an HTML `datetime-local` field
/// sends, or a contract time stamp) in ms since the epoch; `None` when it is not such a time.
/// A time without `Z` is taken as UTC.
pub fn parse_utc_ms(text: &str) -> Option<i64> {
    let t = text.trim();
    let t = t.strip_suffix('Z').unwrap_or(t);
    if t.len() < 16 || !t.is_ascii() {
        return None;
    }
    let b = t.as_bytes();
    if b[4] != b'-' || b[7] != b'-' || (b[10] != b'T' && b[10] != b' ') || b[13] != b':' {
        return None;
    }
    let num = |s: &str| -> Option<i64> {
        if s.is_empty() || !s.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        s.parse().ok()
    };
    let year = num(&t[0..4])?;
    let month = num(&t[5..7])?;
    let day = num(&t[8..10])?;
    let hour = num(&t[11..13])?;
    let minute = num(&t[14..16])?;
    let (mut second, mut milli) = (0, 0);
    let rest = &t[16..];
    if !rest.is_empty() {
        let rest = rest.strip_prefix(':')?;
        let (s, frac) = match rest.split_once('.') {
            Some((s, f)) => (s, Some(f)),
            None => (rest, None),
        };
        if s.len() != 2 {
            return None;
        }
        second = num(s)?;
        if let Some(f) = frac {
            if f.is_empty() || f.len() > 9 {
                return None;
            }
            let digits = num(f)?;
            // Keep milliseconds: scale the fraction to three digits.
            milli = match f.len() {
                1 => digits * 100,
                2 => digits * 10,
                3 => digits,
                n => digits / 10_i64.pow(n as u32 - 3),
            };
        }
    }
    let days_in_month = match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if (year % 4 == 0 && year % 100 != 0) || year % 400 == 0 => 29,
        2 => 28,
        _ => return None,
    };
    if !(1..=days_in_month).contains(&day) || hour > 23 || minute > 59 || second > 59 {
        return None;
    }
    let days = days_from_civil(year, month, day);
    Some(((days * 24 + hour) * 60 + minute) * 60_000 + second * 1000 + milli)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_and_reads_back_contract_stamps() {
        // 2026-11-27T10:00:00.123Z: 20 784 days after the epoch (by hand: 56 years of which
        // 14 leap from 1972 to 2024 → 56·365 + 14 = 20 454 days to 2026-01-01, plus the 304
        // days of January … October and 26 of November).
        let ms = (20_784_i64 * 86_400 + 10 * 3600) * 1000 + 123;
        assert_eq!(utc_ms(ms), "2026-11-27T10:00:00.123Z");
        assert_eq!(parse_utc_ms("2026-11-27T10:00:00.123Z"), Some(ms));
        assert_eq!(parse_utc_ms("2026-11-27T10:00"), Some(ms - 123));
        assert_eq!(parse_utc_ms("2026-11-27T10:00:00.1234Z"), Some(ms));
        assert_eq!(utc_ms(-1), "1969-12-31T23:59:59.999Z");
        for bad in [
            "",
            "2026-02-29T00:00",
            "2026-13-01T00:00",
            "2026-11-27T24:00",
            "2026-11-27T10:00:0",
            "2026-11-27T10:00:00.",
            "２０２６-11-27T10:00",
            "2026-11-27X10:00",
        ] {
            assert_eq!(parse_utc_ms(bad), None, "{bad}");
        }
        assert!(parse_utc_ms("2024-02-29T00:00").is_some());
    }
}
