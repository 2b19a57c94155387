//! Programs that are not UTF-8 (GBK, Latin-1 shop comments): each byte ≥ 0x80 is read as one private-use character, allowed only inside comments, and written back as the same byte.
//!
//! A file that is not valid UTF-8 holds no other non-ASCII characters once mapped, so the
//! mapping is lossless and the rewriters keep working on `&str`. Controllers read words in
//! ASCII only (LinuxCNC, Fanuc, Sinumerik and Heidenhain manuals list ASCII addresses and
//! digits); a byte ≥ 0x80 in a word is refused at its line and column.

use super::dialect::{self, Dialect};
use super::lexer::{self, TokenKind};
use errmap_core::error::{Error, Location, Result};
use std::path::Path;

/// The private-use character that stands for byte 0x80; byte `b` maps to `BASE + (b − 0x80)`.
const BASE: u32 = 0xF780;

/// The byte a mapped character stands for, if it is one.
fn byte_of(c: char) -> Option<u8> {
    let u = c as u32;
    (BASE..BASE + 0x80)
        .contains(&u)
        .then(|| (u - BASE + 0x80) as u8)
}

/// The file's text: as it is when it is UTF-8 (`false`), else with every byte ≥ 0x80 mapped
/// to a private-use character (`true`).
pub(crate) fn decode(raw: Vec<u8>) -> (String, bool) {
    match String::from_utf8(raw) {
        Ok(text) => (text, false),
        Err(e) => {
            let text = e
                .into_bytes()
                .into_iter()
                .map(|b| match b {
                    0..=0x7F => b as char,
                    _ => char::from_u32(BASE + u32::from(b - 0x80)).unwrap_or('\u{FFFD}'),
                })
                .collect();
            (text, true)
        }
    }
}

/// The bytes of a text read by [`decode`] with mapping: mapped characters become their bytes
/// again; anything else (errmap writes ASCII) as UTF-8.
pub(crate) fn encode(text: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(text.len());
    for c in text.chars() {
        match byte_of(c) {
            Some(b) => out.push(b),
            None => out.extend_from_slice(c.encode_utf8(&mut [0; 4]).as_bytes()),
        }
    }
    out
}

/// A mapped character shown in a message as the byte it stands for (`\xC1`).
fn show(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match byte_of(c) {
            Some(b) => out.push_str(&format!("\\x{b:02X}")),
            None => out.push(c),
        }
    }
    out
}

/// An error about a mapped text, with its mapped characters shown as bytes.
pub(crate) fn show_error(e: Error) -> Error {
    match e {
        Error::Input {
            location,
            message,
            hint,
        } => Error::Input {
            location: Location {
                column: location.column.as_deref().map(show),
                ..location
            },
            message: show(&message),
            hint: show(&hint),
        },
        other => other,
    }
}

/// Refuse a mapped text whose bytes ≥ 0x80 stand anywhere but in a comment: in Klartext after
/// `;` or in a `* - …` comment block; in G-code in the comments of its dialect's lexer
/// (`( … )` and `;` in LinuxCNC and Fanuc, `;` in Sinumerik, `;` and after `*` in Heidenhain ISO).
pub(crate) fn check_comments(
    text: &str,
    source: &Path,
    given: Option<Dialect>,
) -> Result<(), crate::CompensateError> {
    if super::klartext::applies(text, source, given) {
        for (i, line) in text.split('\n').enumerate() {
            if let Some(at) = line.find(|c| byte_of(c).is_some()) {
                let comment = line.find(';').is_some_and(|s| s < at)
                    || line
                        .trim_start()
                        .trim_start_matches(|c: char| c.is_ascii_digit())
                        .trim_start()
                        .starts_with('*');
                if !comment {
                    return Err(refusal(source, i as u64 + 1, line, at).into());
                }
            }
        }
        return Ok(());
    }
    let d = dialect::resolve(text, source, given)
        .map_err(|e| crate::CompensateError::from(e).map_diagnostic(show_error))?;
    Ok(lexer::for_each_line(text, d, |line| {
        let content = text.get(line.span.clone()).unwrap_or("");
        for token in &line.tokens {
            if matches!(token.kind, TokenKind::Comment | TokenKind::LineComment) {
                continue;
            }
            let piece = text.get(token.span.clone()).unwrap_or("");
            if let Some(off) = piece.find(|c| byte_of(c).is_some()) {
                let at = token.span.start + off - line.span.start;
                return Err(refusal(source, line.number, content, at));
            }
        }
        Ok(())
    })?)
}

/// The refusal of a byte ≥ 0x80 at byte `at` of `content`, outside a comment.
fn refusal(source: &Path, line: u64, content: &str, at: usize) -> Error {
    let column = content.get(..at).map_or(at, |s| s.chars().count()) + 1;
    let byte = content
        .get(at..)
        .and_then(|s| s.chars().next())
        .and_then(byte_of)
        .unwrap_or(0);
    Error::input(
        Location::cell(source, line, format!("{column} (\\x{byte:02X})")),
        format!(
            "byte 0x{byte:02X} outside a comment: the file is not UTF-8 and a controller reads words in ASCII only (bytes ≥ 0x80 in comments are copied as they are)"
        ),
        "remove the byte or move the text into a comment, or save the program as ASCII",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_maps_back_to_itself() {
        let raw: Vec<u8> = (0..=255u8).collect();
        let (text, mapped) = decode(raw.clone());
        assert!(mapped);
        assert_eq!(encode(&text), raw);
    }

    #[test]
    fn random_bytes_never_panic_and_refusals_name_a_line() {
        // A small LCG: random lines of ASCII words, comments and high bytes in every dialect.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 33) as u8
        };
        let alphabet = b"G01XYZ.-+ ()*;/%\n\r\x80\xc1\xe9\xff0123456789LCCPBEGINPGMMM";
        for _ in 0..400 {
            let len = usize::from(next()) % 80;
            let raw: Vec<u8> = (0..len)
                .map(|_| alphabet[usize::from(next()) % alphabet.len()])
                .collect();
            let (text, mapped) = decode(raw.clone());
            if mapped {
                assert_eq!(encode(&text), raw);
            }
            for given in [
                None,
                Some(Dialect::Linuxcnc),
                Some(Dialect::Fanuc),
                Some(Dialect::Sinumerik),
                Some(Dialect::Heidenhain),
            ] {
                if let Err(Error::Input { location, .. }) =
                    check_comments(&text, Path::new("p.nc"), given)
                        .map_err(errmap_core::error::Diagnose::into_diagnostic)
                {
                    assert!(location.line.is_some() || given.is_none());
                }
            }
        }
    }

    #[test]
    fn utf8_is_read_as_it_is() {
        let (text, mapped) = decode("G1 X1 (ä)\n".as_bytes().to_vec());
        assert!(!mapped);
        assert_eq!(text, "G1 X1 (ä)\n");
    }
}
