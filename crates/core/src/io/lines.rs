//! Line numbers of a byte stream while it is read: a reader wrapper that keeps only the bytes between the last position asked about and the read head, so finding a record's line costs the bytes since the previous record, never a recount from the start.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::io::Read;
use std::rc::Rc;

/// The bytes read but not yet passed by the cursor, and the cursor's (byte, line).
#[derive(Debug)]
struct State {
    /// Chunks as read: (offset of the first byte, bytes).
    chunks: VecDeque<(u64, Vec<u8>)>,
    /// Bytes read so far (offset of the next byte to read).
    read_to: u64,
    cursor_byte: u64,
    /// 1-based line of `cursor_byte`.
    cursor_line: u64,
}

/// A reader that remembers recent bytes so that [`LineIndex::line_of_record`] can turn a
/// record's byte offset into its line number in linear total time.
pub struct LineReader<R> {
    inner: R,
    state: Rc<RefCell<State>>,
}

/// The handle to ask a [`LineReader`] for line numbers while another reader owns it.
#[derive(Debug, Clone)]
pub struct LineIndex {
    state: Rc<RefCell<State>>,
}

/// Wrap `inner`; the index answers for the bytes it hands out.
pub fn track<R: Read>(inner: R) -> (LineReader<R>, LineIndex) {
    let state = Rc::new(RefCell::new(State {
        chunks: VecDeque::new(),
        read_to: 0,
        cursor_byte: 0,
        cursor_line: 1,
    }));
    (
        LineReader {
            inner,
            state: state.clone(),
        },
        LineIndex { state },
    )
}

impl<R: Read> Read for LineReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        if n > 0 {
            let mut s = self.state.borrow_mut();
            let start = s.read_to;
            s.chunks.push_back((start, buf[..n].to_vec()));
            s.read_to += n as u64;
        }
        Ok(n)
    }
}

impl State {
    /// The byte at `offset`, if it has been read and not dropped.
    fn byte(&self, offset: u64) -> Option<u8> {
        // The cursor only moves forward, so the wanted chunk is near the front.
        for (start, bytes) in &self.chunks {
            if offset < *start {
                return None;
            }
            if offset < start + bytes.len() as u64 {
                return Some(bytes[(offset - start) as usize]);
            }
        }
        None
    }

    /// Move the cursor forward to `offset`, counting newlines.
    fn advance_to(&mut self, offset: u64) {
        let offset = offset.min(self.read_to);
        while self.cursor_byte < offset {
            let Some((start, bytes)) = self.chunks.front() else {
                self.cursor_byte = offset;
                break;
            };
            let end = start + bytes.len() as u64;
            if self.cursor_byte >= end {
                self.chunks.pop_front();
                continue;
            }
            let from = (self.cursor_byte - start) as usize;
            let to = (offset.min(end) - start) as usize;
            self.cursor_line += bytes[from..to].iter().filter(|&&b| b == b'\n').count() as u64;
            self.cursor_byte = start + to as u64;
        }
    }
}

impl LineIndex {
    /// 1-based line of the first content byte of a record that the CSV reader says starts at
    /// `offset`: blank lines and lines starting with `comment` between the previous record and
    /// this one are stepped over (the reader counts them into the record). Offsets must not
    /// decrease from one call to the next.
    pub fn line_of_record(&self, offset: u64, comment: Option<u8>) -> u64 {
        let mut s = self.state.borrow_mut();
        s.advance_to(offset);
        loop {
            match s.byte(s.cursor_byte) {
                Some(b'\n') => {
                    s.cursor_byte += 1;
                    s.cursor_line += 1;
                }
                Some(b'\r') => s.cursor_byte += 1,
                Some(b) if Some(b) == comment => {
                    // Skip the comment line up to and including its newline.
                    let mut at = s.cursor_byte;
                    while let Some(b) = s.byte(at) {
                        at += 1;
                        if b == b'\n' {
                            break;
                        }
                    }
                    s.advance_to(at);
                }
                _ => break,
            }
        }
        let line = s.cursor_line;
        // Drop the chunks wholly behind the cursor.
        while let Some((start, bytes)) = s.chunks.front() {
            if start + (bytes.len() as u64) <= s.cursor_byte {
                s.chunks.pop_front();
            } else {
                break;
            }
        }
        line
    }

    #[cfg(test)]
    /// Bytes held for line counting (what the reader read ahead of the cursor).
    pub fn held_bytes(&self) -> usize {
        self.state
            .borrow()
            .chunks
            .iter()
            .map(|(_, b)| b.len())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reader that hands out `step` bytes at a time, to cross chunk borders everywhere.
    struct Trickle<'a> {
        data: &'a [u8],
        step: usize,
    }

    impl Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.step.min(buf.len()).min(self.data.len());
            buf[..n].copy_from_slice(&self.data[..n]);
            self.data = &self.data[n..];
            Ok(n)
        }
    }

    #[test]
    fn lines_of_offsets_match_a_count_from_the_start() {
        let text = b"a\n\n# note\r\n\r\nbb\ncc\n\n\n#x\nd";
        for step in [1, 2, 3, 7, 64] {
            let (mut r, index) = track(Trickle { data: text, step });
            let mut all = Vec::new();
            r.read_to_end(&mut all).unwrap();
            // Record starts as the csv crate reports them: after each terminator.
            assert_eq!(index.line_of_record(0, Some(b'#')), 1);
            assert_eq!(index.line_of_record(2, Some(b'#')), 5, "step {step}");
            assert_eq!(index.line_of_record(16, Some(b'#')), 6, "step {step}");
            assert_eq!(index.line_of_record(19, Some(b'#')), 10, "step {step}");
            // Only the chunk under the cursor is still held.
            assert!(index.held_bytes() <= step, "step {step}");
        }
    }
}
