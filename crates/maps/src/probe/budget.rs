//! The memory bound of one part: the points a probe file or scan holds, counted before it is read, and the memory mapping them needs, against `--max-memory-mb` (job key `max_memory_mb`).
//!
//! Every stage of a part keeps a constant number of bytes per point (the points as read, the
//! triangulation of gross-error rejection, the training bins, the kriging's sites), so the need
//! is [`BASE_MB`] plus [`BYTES_PER_POINT`] per point, measured on generated scans of 10⁵ and
//! 10⁶ points with some margin (docs/job.md, "Dense scans"). The points are counted from the
//! file's lines (a text format holds at most one point per line) or from a binary PLY header,
//! in one pass that keeps nothing, so a scan too large is refused before it is read.

use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Default bound on the memory one part may need, MB.
pub const DEFAULT_MAX_MEMORY_MB: u64 = 8192;

/// Memory a part needs besides its points, MB.
pub const BASE_MB: u64 = 100;

/// Memory a part needs per point, bytes (peak over its stages).
pub const BYTES_PER_POINT: u64 = 1500;

/// The bound `--max-memory-mb` gave for this process (0: none given).
static FLAG_MB: AtomicU64 = AtomicU64::new(0);

/// Record `--max-memory-mb`; it wins over a job's `max_memory_mb`.
pub fn set_max_memory_mb(mb: u64) {
    FLAG_MB.store(mb, Ordering::Relaxed);
}

/// The bound in force: `--max-memory-mb`, else the job's key, else the default.
pub fn max_memory_mb(job_key: Option<u64>) -> u64 {
    match FLAG_MB.load(Ordering::Relaxed) {
        0 => job_key.unwrap_or(DEFAULT_MAX_MEMORY_MB),
        mb => mb,
    }
}

/// The memory a part of `points` points needs, MB.
pub fn need_mb(points: u64) -> u64 {
    BASE_MB + points.saturating_mul(BYTES_PER_POINT).div_ceil(1_000_000)
}

/// At most how many points the file holds: its lines, or a binary PLY's vertex count.
pub fn count_points(path: &Path) -> Result<u64> {
    let file = std::fs::File::open(path).map_err(|e| Error::read(path, e))?;
    let mut reader = BufReader::with_capacity(1 << 16, file);
    let starts_ply = reader
        .fill_buf()
        .map_err(|e| Error::read(path, e))?
        .starts_with(b"ply");
    if starts_ply {
        let mut line = String::new();
        let mut vertices = None;
        let mut binary = false;
        // The header is text up to `end_header`; a damaged one is left to the reader to name.
        for _ in 0..200 {
            line.clear();
            let mut bytes = Vec::new();
            if reader
                .read_until(b'\n', &mut bytes)
                .map_err(|e| Error::read(path, e))?
                == 0
            {
                break;
            }
            line.push_str(&String::from_utf8_lossy(&bytes));
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                ["format", f, ..] => binary = *f != "ascii",
                ["element", "vertex", n] => vertices = n.parse::<u64>().ok(),
                ["end_header"] => break,
                _ => {}
            }
        }
        if binary {
            if let Some(n) = vertices {
                return Ok(n);
            }
        }
    }
    let mut lines = 1u64;
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = reader.read(&mut buf).map_err(|e| Error::read(path, e))?;
        if n == 0 {
            break;
        }
        lines += buf[..n].iter().filter(|&&b| b == b'\n').count() as u64;
    }
    Ok(lines)
}

/// Refuse a probe file whose points need more than `max_mb` (exit 2, naming the bound, the
/// flag and the job key).
pub fn check(path: &Path, max_mb: u64) -> Result<()> {
    let points = count_points(path)?;
    let need = need_mb(points);
    if need <= max_mb {
        return Ok(());
    }
    Err(Error::input(
        Location::file(path),
        format!(
            "up to {points} points: mapping them needs about {need} MB, more than the memory bound of {max_mb} MB"
        ),
        format!(
            "raise the bound with {} (job key max_memory_mb) to {need} or more if the machine has the memory, or thin the scan",
            words(Setting::MaxMemory)
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_are_counted_from_lines_or_the_ply_header() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("p.csv");
        std::fs::write(&csv, "x_mm,y_mm,z_mm\n1,2,3\n4,5,6\n").unwrap();
        assert_eq!(count_points(&csv).unwrap(), 4);
        let ply = dir.path().join("p.ply");
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n".to_vec();
        bytes.extend(std::iter::repeat_n(10u8, 48)); // newline bytes in the binary part
        std::fs::write(&ply, bytes).unwrap();
        assert_eq!(count_points(&ply).unwrap(), 2);
    }

    #[test]
    fn a_file_beyond_the_bound_is_refused_naming_the_flag() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("scan.csv");
        let text: String = (0..1000).map(|k| format!("{k},0,0\n")).collect();
        std::fs::write(&csv, text).unwrap();
        // 1001 lines: 100 MB + 1001 · 1500 B = 101.5 → 102 MB.
        assert_eq!(need_mb(1001), 102);
        check(&csv, 102).unwrap();
        let err = check(&csv, 101).unwrap_err();
        assert_eq!(err.kind(), "input");
        let text = err.to_string();
        assert!(
            text.contains("scan.csv") && text.contains("101 MB") && text.contains("102 MB"),
            "{text}"
        );
        assert!(
            text.contains("`max_memory_mb` (job key max_memory_mb)"),
            "{text}"
        );
    }
}
