//! Programs that are not UTF-8: bytes ≥ 0x80 (GBK, Latin-1) in comments are copied as they are; outside a comment they are refused at their line and column.

mod common;

use std::path::Path;

/// Compensate `program` (bytes) with the flat 20 µm map at every height; exit code, output
/// bytes (empty when refused) and stderr.
fn compensate(dir: &Path, name: &str, program: &[u8], dialect: &str) -> (i32, Vec<u8>, String) {
    std::fs::write(dir.join("model.json"), common::FLAT_MODEL_20UM).unwrap();
    std::fs::write(dir.join(name), program).unwrap();
    let out = format!("out-{name}");
    let run = common::errmap(
        dir,
        &[
            "compensate",
            "--model",
            "model.json",
            "--zone",
            "all",
            "--dialect",
            dialect,
            name,
            "-o",
            &out,
        ],
    );
    let bytes = std::fs::read(dir.join(&out)).unwrap_or_default();
    (run.code, bytes, run.stderr)
}

/// The lines of `bytes`, each with its terminator.
fn lines(bytes: &[u8]) -> Vec<&[u8]> {
    bytes.split_inclusive(|&b| b == b'\n').collect()
}

#[test]
fn gbk_and_latin1_comments_are_copied_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    // GBK title, Latin-1 `réglage` and `départ`, GBK in a comment on a cut.
    let program: &[u8] = b"(\xc1\xa2\xcf\xb3\xb5\xb6 GBK)\r\nG21 G90 G17 (r\xe9glage)\r\nG0 X10 Y10 Z5 ; d\xe9part\r\nG1 Z-1 F100\r\nG1 X20 (\xc7\xf2\xcd\xb7)\r\nG0 Z5\r\nM2\r\n";
    let (code, out, stderr) = compensate(dir.path(), "latin.ngc", program, "linuxcnc");
    assert_eq!(code, 0, "{stderr}");
    let (inp, got) = (lines(program), lines(&out));
    // The unchanged lines: the three before the first cut and the two after the last.
    assert_eq!(&got[..3], &inp[..3]);
    assert_eq!(&got[got.len() - 2..], &inp[inp.len() - 2..]);
    // The cut's comment keeps its GBK bytes, on a line lowered by E = 0.02 mm.
    let comment: &[u8] = b"(\xc7\xf2\xcd\xb7)\r\n";
    let with = got
        .iter()
        .find(|l| l.ends_with(comment))
        .expect("the comment of the cut is kept");
    assert!(
        with.windows(8).any(|w| w == b"Z-1.0200"),
        "{}",
        String::from_utf8_lossy(with)
    );
    // Nothing else in the output is outside ASCII: every byte ≥ 0x80 came from a comment.
    let high = |b: &[u8]| b.iter().filter(|&&c| c >= 0x80).count();
    assert_eq!(high(&out), high(program));
}

#[test]
fn klartext_gbk_comment_blocks_are_copied_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let program: &[u8] = b"0 BEGIN PGM K MM\r\n1 ; \xc1\xa2\xcf\xb3\r\n2 * - T1 \xc8\xce\xd2\xe2\r\n3 L X+0 Y+0 Z+5 R0 FMAX\r\n4 L Z-1 F100 ; \xe9\r\n5 L X+10\r\n6 L Z+5 FMAX\r\n7 END PGM K MM\r\n";
    let (code, out, stderr) = compensate(dir.path(), "k.h", program, "heidenhain");
    assert_eq!(code, 0, "{stderr}");
    let (inp, got) = (lines(program), lines(&out));
    assert_eq!(&got[..4], &inp[..4]);
    assert!(got
        .iter()
        .any(|l| l.ends_with(b"Z-1.0200 F100 ; \xe9\r\n") || l.ends_with(b"F100 ; \xe9\r\n")));
    assert_eq!(
        out.iter().filter(|&&c| c >= 0x80).count(),
        program.iter().filter(|&&c| c >= 0x80).count()
    );
}

#[test]
fn a_byte_above_0x7f_in_a_word_is_refused_at_its_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let (code, out, stderr) = compensate(
        dir.path(),
        "bad.ngc",
        b"(\xc1\xa2)\nG21 G90 G17\nG0 X1\xe9 Y2 Z5\nM2\n",
        "linuxcnc",
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(out.is_empty());
    assert!(stderr.contains("bad.ngc:3, column 6 (\\xE9)"), "{stderr}");
    assert!(stderr.contains("byte 0xE9 outside a comment"), "{stderr}");

    let (code, _, stderr) = compensate(
        dir.path(),
        "bad.h",
        b"0 BEGIN PGM K MM\n1 L X+0 Y+0 Z+5 R0 FMAX\n2 L X+1\xe9 Z-1 F100\n3 END PGM K MM\n",
        "heidenhain",
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("bad.h:3, column 8 (\\xE9)"), "{stderr}");
}

#[test]
fn each_dialect_has_its_own_comments() {
    let dir = tempfile::tempdir().unwrap();
    // Sinumerik: `;` is a comment, its bytes are copied.
    let program: &[u8] =
        b"; \xc1\xa2\nG71 G90 G17\nG0 X0 Y0 Z5 ; d\xe9part\nG1 Z-1 F100\nG1 X10\nG0 Z5\nM30\n";
    let (code, out, stderr) = compensate(dir.path(), "s.mpf", program, "sinumerik");
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(&lines(&out)[..3], &lines(program)[..3]);
    // … but parentheses are not (they group expressions): refused at the byte.
    let (code, _, stderr) = compensate(
        dir.path(),
        "p.mpf",
        b"G71 G90 G17\nG0 X0 Y0 Z5 (d\xe9part)\nM30\n",
        "sinumerik",
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("p.mpf:2, column 15 (\\xE9)"), "{stderr}");
    // Fanuc: `( … )` is a comment on an O line and on a cut.
    let program: &[u8] = b"%\nO1000 (\xc1\xa2)\nG21 G90 G17\nG0 X0. Y0. Z5.\nG1 Z-1. F100.\nG1 X10. (d\xe9part)\nG0 Z5.\nM30\n%\n";
    let (code, out, stderr) = compensate(dir.path(), "f.nc", program, "fanuc");
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(&lines(&out)[..4], &lines(program)[..4]);
    assert!(out.windows(8).any(|w| w == b"(d\xe9part)"));
}
