//! Words of a G-code line, with the column each came from: the one tokenizer behind the simulator's reader
//! (which refuses what it does not understand, naming the column) and the streamer's program model (which
//! maps the same faults to GRBL's error codes).
//!
//! Syntax, as both LinuxCNC and GRBL 1.1 read it: comments `( … )` (not nested) and `;` to the end of the
//! line; spaces and tabs anywhere outside comments, also inside numbers (`X1 0.5` is `X10.5`); letters in
//! either case; a number is an optional sign, digits and at most one decimal point (no exponent, as GRBL's
//! `read_float`). A line that holds only `%` is a program delimiter.

use std::fmt;

/// One word: an upper-case letter, its value, and the 0-based column (in characters) of the letter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Word {
    /// Upper-case letter.
    pub letter: char,
    /// Its value.
    pub value: f64,
    /// 0-based column of the letter in the source line, in characters.
    pub column: usize,
}

/// A lexed line.
#[derive(Clone, Debug, PartialEq)]
pub enum Block {
    /// A line holding only `%` (and spaces).
    Percent,
    /// The words of the line, in order (empty for a blank or comment-only line).
    Words(Vec<Word>),
}

/// What is wrong with a line, and where (0-based column, in characters).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LexError {
    /// 0-based column of the offending character.
    pub column: usize,
    /// What it is.
    pub kind: LexErrorKind,
}

/// The faults the tokenizer finds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LexErrorKind {
    /// A `(` inside a comment.
    NestedComment,
    /// A `(` never closed on its line.
    UnclosedComment,
    /// `%` on a line with other content.
    PercentNotAlone,
    /// Block delete `/`.
    BlockDelete,
    /// A `#` parameter.
    Parameter,
    /// A `[ ]` expression, or a letter followed by one.
    Expression(char),
    /// An `O` word (subroutines, loops, conditionals).
    OWord,
    /// A letter without a number after it (GRBL `error:2`).
    BadNumber(char),
    /// A character where a letter was expected (GRBL `error:1`).
    Unexpected(char),
}

impl LexErrorKind {
    /// The error code GRBL 1.1 answers for the same fault in a cleaned block: 2 (bad number format) for a
    /// letter without a readable number, 20 (unsupported command) for an `O` word, 1 (expected command
    /// letter) otherwise.
    #[must_use]
    pub fn grbl_code(&self) -> u16 {
        match self {
            LexErrorKind::BadNumber(_) => 2,
            LexErrorKind::Expression(l) if *l != '[' => 2,
            LexErrorKind::OWord => 20,
            _ => 1,
        }
    }
}

impl fmt::Display for LexErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LexErrorKind::NestedComment => write!(f, "nested comment: `(` inside a comment"),
            LexErrorKind::UnclosedComment => write!(f, "comment `(` is not closed on this line"),
            LexErrorKind::PercentNotAlone => write!(f, "`%` must stand alone on its line"),
            LexErrorKind::BlockDelete => write!(f, "block delete `/` is not supported"),
            LexErrorKind::Parameter => write!(f, "parameters (`#`) are not supported"),
            LexErrorKind::Expression('[') => write!(f, "expressions (`[ ]`) are not supported"),
            LexErrorKind::Expression(l) => {
                write!(
                    f,
                    "`{l}` with a parameter or expression: only plain numbers are supported"
                )
            }
            LexErrorKind::OWord => write!(f, "O-words (subroutines, loops, conditionals) are not supported"),
            LexErrorKind::BadNumber(l) => write!(f, "`{l}` needs a number"),
            LexErrorKind::Unexpected(c) if c.is_control() => {
                write!(f, "control character U+{:04X} where a word was expected", u32::from(*c))
            }
            LexErrorKind::Unexpected(c) => write!(f, "unexpected character `{c}`"),
        }
    }
}

impl fmt::Display for LexError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "column {}: {}", self.column + 1, self.kind)
    }
}

impl std::error::Error for LexError {}

/// Split one source line into words.
pub fn lex(line: &str) -> Result<Block, LexError> {
    if line.trim() == "%" {
        return Ok(Block::Percent);
    }
    let err = |column: usize, kind: LexErrorKind| Err(LexError { column, kind });
    let c: Vec<char> = line.chars().collect();
    let mut words = vec![];
    let mut k = 0;
    while k < c.len() {
        match c[k] {
            ' ' | '\t' | '\r' | '\u{feff}' => k += 1,
            '(' => {
                let mut e = k + 1;
                while e < c.len() && c[e] != ')' {
                    if c[e] == '(' {
                        return err(e, LexErrorKind::NestedComment);
                    }
                    e += 1;
                }
                if e == c.len() {
                    return err(k, LexErrorKind::UnclosedComment);
                }
                k = e + 1;
            }
            ';' => break,
            '%' => return err(k, LexErrorKind::PercentNotAlone),
            '/' => return err(k, LexErrorKind::BlockDelete),
            '#' => return err(k, LexErrorKind::Parameter),
            '[' => return err(k, LexErrorKind::Expression('[')),
            'o' | 'O' => return err(k, LexErrorKind::OWord),
            l if l.is_ascii_alphabetic() => {
                let (word, next) = number(&c, k)?;
                words.push(word);
                k = next;
            }
            ch => return err(k, LexErrorKind::Unexpected(ch)),
        }
    }
    Ok(Block::Words(words))
}

/// Read the number after the letter at `c[at]`; returns the word and the index after it.
fn number(c: &[char], at: usize) -> Result<(Word, usize), LexError> {
    let letter = c[at].to_ascii_uppercase();
    let mut k = at + 1;
    let mut num = String::new();
    let mut digits = 0;
    let mut dot = false;
    while k < c.len() {
        match c[k] {
            ' ' | '\t' => {}
            s @ ('+' | '-') if num.is_empty() => num.push(s),
            '.' if !dot => {
                dot = true;
                num.push('.');
            }
            d if d.is_ascii_digit() => {
                digits += 1;
                num.push(d);
            }
            '#' | '[' if digits == 0 => {
                return Err(LexError {
                    column: k,
                    kind: LexErrorKind::Expression(letter),
                })
            }
            _ => break,
        }
        k += 1;
    }
    let bad = LexError {
        column: at,
        kind: LexErrorKind::BadNumber(letter),
    };
    if digits == 0 {
        return Err(bad);
    }
    let value: f64 = num.parse().map_err(|_| bad.clone())?;
    if !value.is_finite() {
        return Err(bad);
    }
    Ok((
        Word {
            letter,
            value,
            column: at,
        },
        k,
    ))
}

/// A G or M code in tenths (`G91.1` → 911), or `None` when it is negative or not a multiple of 0.1.
#[must_use]
pub fn tenths(v: f64) -> Option<i64> {
    let t = (v * 10.0).round();
    ((v * 10.0 - t).abs() < 1e-6 && v >= 0.0 && t < 1e9).then_some(t as i64)
}

/// The name of a G code given in tenths (`911` → `G91.1`).
#[must_use]
pub fn g_name(t: i64) -> String {
    if t % 10 == 0 {
        format!("G{}", t / 10)
    } else {
        format!("G{}.{}", t / 10, t % 10)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(s: &str) -> Vec<(char, f64, usize)> {
        match lex(s).unwrap() {
            Block::Words(w) => w.iter().map(|w| (w.letter, w.value, w.column)).collect(),
            Block::Percent => panic!("percent"),
        }
    }

    #[test]
    fn words_with_columns_comments_and_spaces() {
        assert_eq!(
            words("g1 x1 0.5 (a comment) y-2 ; tail Z9"),
            [('G', 1.0, 0), ('X', 10.5, 3), ('Y', -2.0, 22)]
        );
        assert_eq!(words("  (only a comment)"), []);
        assert_eq!(lex(" % ").unwrap(), Block::Percent);
    }

    #[test]
    fn faults_name_their_column() {
        for (s, col, kind) in [
            ("G0 X1 (open", 6, LexErrorKind::UnclosedComment),
            ("(a (b))", 3, LexErrorKind::NestedComment),
            ("G0 %", 3, LexErrorKind::PercentNotAlone),
            ("/G0", 0, LexErrorKind::BlockDelete),
            ("#1=2", 0, LexErrorKind::Parameter),
            ("G1 X[1]", 4, LexErrorKind::Expression('X')),
            ("O100 sub", 0, LexErrorKind::OWord),
            ("G1 X", 3, LexErrorKind::BadNumber('X')),
            ("X1.2.3", 4, LexErrorKind::Unexpected('.')),
            ("G0 $", 3, LexErrorKind::Unexpected('$')),
            ("G0 X1\u{7}", 5, LexErrorKind::Unexpected('\u{7}')),
        ] {
            let e = lex(s).expect_err(s);
            assert_eq!((e.column, &e.kind), (col, &kind), "{s:?}");
        }
        assert_eq!(LexErrorKind::BadNumber('X').grbl_code(), 2);
        assert_eq!(LexErrorKind::Unexpected('$').grbl_code(), 1);
    }

    #[test]
    fn a_number_too_long_for_f64_is_refused_not_infinite() {
        let s = format!("G1 X{}", "9".repeat(309));
        assert_eq!(lex(&s).unwrap_err().kind, LexErrorKind::BadNumber('X'));
    }

    #[test]
    fn codes_in_tenths() {
        assert_eq!(tenths(91.1), Some(911));
        assert_eq!(tenths(1.0), Some(10));
        assert_eq!(tenths(1.05), None);
        assert_eq!(tenths(-1.0), None);
        assert_eq!(g_name(911), "G91.1");
        assert_eq!(g_name(10), "G1");
    }
}
