//! GRBL's serial line reader (`protocol_main_loop` in `protocol.c`), byte by byte as the main loop takes
//! bytes out of the receive buffer: `(…)` and `;…` comments, whitespace, control characters and `/` are
//! dropped, letters upper-cased, and a block longer than 79 characters (the 80-byte line buffer) is marked
//! as overflowing, to be answered `error:11`.
//!
//! It is not [`program::clean`](crate::apps::stream::program::clean) run on a whole line because it must work
//! on a byte stream whose lines arrive in pieces, and because `clean` is the host's view: it drops a line
//! that is just `%`, which GRBL 1.1h keeps and rejects with `error:1` (its `%` support is a TODO).

use crate::apps::stream::program::MAX_BLOCK_CHARS;

/// The line being assembled and the comment / overflow flags (GRBL's `line_flags`).
#[derive(Debug)]
pub(super) struct LineReader {
    line: Vec<u8>,
    in_paren: bool,
    in_semicolon: bool,
    overflow: bool,
}

/// A complete line: the cleaned block, and whether it overflowed the line buffer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct ReadLine {
    pub(super) text: String,
    pub(super) overflow: bool,
}

impl LineReader {
    pub(super) fn new() -> LineReader {
        LineReader {
            line: Vec::with_capacity(MAX_BLOCK_CHARS + 1),
            in_paren: false,
            in_semicolon: false,
            overflow: false,
        }
    }

    /// Forget a partial line (a soft reset, a dropped link).
    pub(super) fn clear(&mut self) {
        self.line.clear();
        self.in_paren = false;
        self.in_semicolon = false;
        self.overflow = false;
    }

    /// Take one byte; at the end of a line (`\n` or `\r`) returns it.
    pub(super) fn push(&mut self, c: u8) -> Option<ReadLine> {
        if c == b'\n' || c == b'\r' {
            let read = ReadLine {
                text: String::from_utf8_lossy(&self.line).into_owned(),
                overflow: self.overflow,
            };
            self.clear();
            return Some(read);
        }
        if self.in_paren || self.in_semicolon {
            if c == b')' {
                self.in_paren = false;
            }
        } else if c <= b' ' || c == b'/' {
        } else if c == b'(' {
            self.in_paren = true;
        } else if c == b';' {
            self.in_semicolon = true;
        } else if self.line.len() >= MAX_BLOCK_CHARS {
            self.overflow = true;
        } else {
            self.line.push(c.to_ascii_uppercase());
        }
        None
    }
}

/// The `N` word of a cleaned block, if it starts with one.
pub(super) fn leading_line_number(text: &str) -> Option<u32> {
    let rest = text.strip_prefix('N')?;
    let end = rest.find(|c: char| !c.is_ascii_digit()).unwrap_or(rest.len());
    rest[..end].parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(bytes: &[u8]) -> Vec<ReadLine> {
        let mut r = LineReader::new();
        bytes.iter().filter_map(|&b| r.push(b)).collect()
    }

    #[test]
    fn strips_comments_and_spaces_and_upper_cases() {
        let lines = read(b"g1 x1 (a comment) y2 ; tail (\n/G0 X0\r%\n");
        let texts: Vec<&str> = lines.iter().map(|l| l.text.as_str()).collect();
        assert_eq!(texts, ["G1X1Y2", "G0X0", "%"]);
        assert!(lines.iter().all(|l| !l.overflow));
    }

    #[test]
    fn marks_a_block_over_79_characters() {
        let long = format!("G1X{}\n", "1".repeat(MAX_BLOCK_CHARS - 3));
        assert!(!read(long.as_bytes())[0].overflow);
        let longer = format!("G1X{}\n", "1".repeat(MAX_BLOCK_CHARS - 2));
        assert!(read(longer.as_bytes())[0].overflow);
    }

    #[test]
    fn reads_a_leading_line_number() {
        assert_eq!(leading_line_number("N12G1X1"), Some(12));
        assert_eq!(leading_line_number("G1N12"), None);
    }
}
