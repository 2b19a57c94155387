//! What a written document records of its inputs and its time: the SHA-256 of files and bytes, and the UTC time of writing (or `SOURCE_DATE_EPOCH`).

use crate::error::{Error, Result};
use sha2::{Digest, Sha256};
use std::io::Read;
use std::path::Path;

/// Now (or `SOURCE_DATE_EPOCH`, for reproducible runs) as UTC RFC 3339, to the second.
pub fn utc_now() -> String {
    let secs = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|v| v.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs() as i64)
        });
    utc_rfc3339(secs)
}

/// Seconds since 1970-01-01T00:00:00Z as `YYYY-MM-DDThh:mm:ssZ` (proleptic Gregorian calendar;
/// days to date by Hinnant's `civil_from_days`).
pub fn utc_rfc3339(secs: i64) -> String {
    format!("{}Z", civil_seconds(secs))
}

/// Milliseconds since 1970-01-01T00:00:00Z as `YYYY-MM-DDThh:mm:ss.mmmZ`: the live loop's and
/// the monitor's time stamps.
///
/// ```
/// // 1 795 766 400 s is 2026-11-27T08:00:00Z (`date -u -d @1795766400`).
/// let stamp = errmap_core::io::stamp::utc_rfc3339_ms(1_795_766_400_123);
/// assert_eq!(stamp, "2026-11-27T08:00:00.123Z");
/// assert_eq!(errmap_core::io::stamp::utc_rfc3339_ms(-1), "1969-12-31T23:59:59.999Z");
/// ```
pub fn utc_rfc3339_ms(ms: i64) -> String {
    format!(
        "{}.{:03}Z",
        civil_seconds(ms.div_euclid(1000)),
        ms.rem_euclid(1000)
    )
}

/// `YYYY-MM-DDThh:mm:ss` of seconds since the epoch.
fn civil_seconds(secs: i64) -> String {
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Lower-case hex SHA-256 of a file's bytes.
pub fn sha256_file(path: &Path) -> Result<String> {
    let mut file = std::fs::File::open(path).map_err(|e| Error::read(path, e))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file.read(&mut buf).map_err(|e| Error::read(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

/// Lower-case hex SHA-256 of bytes.
pub fn sha256_bytes(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
