//! Fixed-point text of coordinates (the writers live in `errmap_core::numeric::format`), and how many decimals the program uses.

use super::super::lexer::{Line, TokenKind, WordValue};

pub(super) use errmap_core::numeric::format::{
    decimal_units, fixed as format_decimals_slow, push_units,
};
pub use errmap_core::numeric::format::{format_coord, format_decimals};

/// Most decimals written in an X/Y/Z/I/J/K/R number of the program, capped at 9.
pub(super) fn coordinate_decimals(text: &str, line: &Line) -> usize {
    let mut most = 0;
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
    most.min(9)
}
