//! The pseudo-Boolean competition `.opb` objective format, read and written.
//!
//! Accepted: comment lines starting with `*` (a `* #variable= N …` header declares the
//! variables `x1 … xN`; then any other name is an error), one objective `min: … ;` or
//! `max: … ;` (a maximisation is stored negated, as a minimisation), spanning any number of
//! lines, whose terms are a coefficient followed by zero or more literals (`x3`, `~x3`):
//! `min: +3 x1 x2 -2 ~x3 ;`. Non-linear terms are products of literals. Coefficients may be
//! decimals. A term with no literal is a constant; our writer records the constant in a
//! `* #constant= c` comment (standard OPB has none) so that writing and reading back is
//! lossless. Constraints are
//! rejected with a clear error (urbansem minimises unconstrained objectives).
//! Roussel & Manquinho, "Input/output format and solver requirements for the competitions
//! of pseudo-Boolean solvers" (PB competition format description, 2012).
//!
//! ```
//! use pbo::opb::{parse_opb, write_opb};
//! let p = parse_opb("min: +3 x1 x2 -2 ~x3 ;", "inline").unwrap();
//! assert_eq!(p.names, ["x1", "x2", "x3"]);
//! assert_eq!(p.poly.evaluate(&[true, true, false]), 1.0);
//! let back = parse_opb(&write_opb(&p), "again").unwrap();
//! assert_eq!(back.poly.evaluate(&[true, true, false]), 1.0);
//! ```

use crate::polynomial::{Literal, Polynomial, TermBatch};
use rustc_hash::FxHashMap;
use std::fmt::Write as _;
use std::path::Path;
use thiserror::Error;

/// Why an `.opb` file could not be read.
#[derive(Debug, Error)]
pub enum OpbError {
    /// The file could not be read at all.
    #[error("{path}: cannot read the file")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Malformed syntax at a position.
    #[error("{path}:{line}:{col}: {message}")]
    Syntax {
        /// The file (or a label for in-memory text).
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column (in characters).
        col: usize,
        /// What was found and what was expected.
        message: String,
    },
    /// A coefficient that is not a finite number (NaN, inf, or out of range).
    #[error("{path}:{line}:{col}: coefficient {text:?} is not a finite number")]
    BadCoefficient {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        col: usize,
        /// The offending token.
        text: String,
    },
    /// A variable the header did not declare.
    #[error("{path}:{line}:{col}: unknown variable {name:?}: the header declares #variable= {declared} (x1 … x{declared})")]
    UnknownVariable {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        col: usize,
        /// The variable name found.
        name: String,
        /// The number of variables the header declares.
        declared: usize,
    },
    /// The file has constraints; only objectives are supported.
    #[error("{path}:{line}:{col}: constraints are not supported: urbansem minimises an unconstrained objective (found {found:?})")]
    Constraint {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        col: usize,
        /// The start of the constraint.
        found: String,
    },
    /// No `min:`/`max:` objective in the file.
    #[error("{path}: no objective found: expected a line `min: <terms> ;`")]
    NoObjective {
        /// The file.
        path: String,
    },
}

/// Whether the file asked to minimise or maximise (a maximisation is stored negated).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sense {
    /// `min:` objective.
    Minimize,
    /// `max:` objective; [`OpbProblem::poly`] holds its negation.
    Maximize,
}

/// An objective read from an `.opb` file.
#[derive(Debug, Clone)]
pub struct OpbProblem {
    /// The function to minimise (negated objective for `max:`).
    pub poly: Polynomial,
    /// Variable names by index.
    pub names: Vec<String>,
    /// The objective sense in the file.
    pub sense: Sense,
    /// The header's `#variable=` count, if any. When it exceeds the file's length, only the
    /// variables of the objective are in [`OpbProblem::names`] (the others are free).
    pub declared: Option<usize>,
}

impl OpbProblem {
    /// The index of a variable name.
    pub fn var_index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

/// Reads an `.opb` objective from a file.
pub fn read_opb(path: &Path) -> Result<OpbProblem, OpbError> {
    let label = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| OpbError::Io {
        path: label.clone(),
        source,
    })?;
    parse_opb(&text, &label)
}

/// A token with its 1-based line; the column is computed only for error messages.
#[derive(Clone, Copy)]
struct Token<'a> {
    text: &'a str,
    line: usize,
    /// The whole line the token is on.
    line_text: &'a str,
}

impl Token<'_> {
    /// Byte offset of the token in its line.
    fn offset(&self) -> usize {
        self.text.as_ptr() as usize - self.line_text.as_ptr() as usize
    }

    /// 1-based column in characters (counted once, when an error needs it).
    fn col(&self) -> usize {
        self.line_text
            .get(..self.offset())
            .map_or(1, |before| before.chars().count() + 1)
    }

    /// 1-based column just after the token.
    fn end_col(&self) -> usize {
        self.col() + self.text.chars().count()
    }
}

/// The tokens of the non-comment lines, produced lazily: linear in the text even when the
/// whole objective is one line (no position is recounted per token).
struct Tokens<'a> {
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    rest: &'a str,
    line: usize,
    line_text: &'a str,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Self {
        Tokens {
            lines: text.lines().enumerate(),
            rest: "",
            line: 0,
            line_text: "",
        }
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = Token<'a>;

    fn next(&mut self) -> Option<Token<'a>> {
        loop {
            self.rest = trim_start_fast(self.rest);
            if !self.rest.is_empty() {
                break;
            }
            let (i, line) = self.lines.next()?;
            if line.trim_start().starts_with('*') {
                continue;
            }
            self.line = i + 1;
            self.line_text = line;
            self.rest = line;
        }
        // `;` is a token of its own.
        let len = if self.rest.starts_with(';') {
            1
        } else {
            token_len(self.rest)
        };
        let (text, rest) = self.rest.split_at(len);
        self.rest = rest;
        Some(Token {
            text,
            line: self.line,
            line_text: self.line_text,
        })
    }
}

/// Whether an ASCII byte is whitespace as `char::is_whitespace` says (which includes the
/// vertical tab that `u8::is_ascii_whitespace` leaves out).
fn is_ascii_space(b: u8) -> bool {
    b.is_ascii_whitespace() || b == 0x0B
}

/// `str::trim_start`, with a byte loop over ASCII (the tokenizer's hot path).
fn trim_start_fast(s: &str) -> &str {
    let skip = s.bytes().take_while(|&b| is_ascii_space(b)).count();
    // `skip` ends at an ASCII byte, a char boundary; non-ASCII space is left to std.
    s.get(skip..).map_or("", str::trim_start)
}

/// Length in bytes of the token at the start of `s`: up to whitespace or `;`.
fn token_len(s: &str) -> usize {
    let bytes = s.as_bytes();
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        if b < 0x80 {
            if is_ascii_space(b) || b == b';' {
                return i;
            }
            i += 1;
        } else {
            match s.get(i..).and_then(|r| r.chars().next()) {
                Some(c) if c.is_whitespace() => return i,
                Some(c) => i += c.len_utf8(),
                None => return i,
            }
        }
    }
    i
}

/// The `* #variable= N` and `* #constant= c` header values of the comment lines.
struct Header {
    declared: Option<usize>,
    constant: Option<f64>,
}

fn read_header(text: &str, path: &str) -> Result<Header, OpbError> {
    let mut header = Header {
        declared: None,
        constant: None,
    };
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let Some(comment) = line.trim_start().strip_prefix('*') else {
            continue;
        };
        if let Some(n) = header_value(comment, "#variable=") {
            let n = n.parse::<usize>().map_err(|_| OpbError::Syntax {
                path: path.to_owned(),
                line: line_no,
                col: column_of(line, "#variable="),
                message: format!("expected a variable count after #variable=, found {n:?}"),
            })?;
            header.declared = Some(n);
        }
        if let Some(c) = header_value(comment, "#constant=") {
            let col = column_of(line, "#constant=") + "#constant=".len();
            header.constant = Some(parse_coefficient(c, path, line_no, || col)?);
        }
    }
    Ok(header)
}

/// 1-based character column of `key` in `line` (1 when absent).
fn column_of(line: &str, key: &str) -> usize {
    line.find(key)
        .map_or(1, |at| line[..at].chars().count() + 1)
}

/// How variable names become indices.
enum Naming {
    /// No header: names are free-form, numbered in order of first appearance.
    Free(FxHashMap<String, u32>),
    /// A header declares `x1 … xN` and N fits the file: `xk` is variable `k - 1`.
    Declared(usize),
    /// A header declares more variables than the file could mention: only the variables of
    /// the objective are kept, numbered in order of first appearance and re-sorted by `k`
    /// at the end (the others do not occur in the objective, so any value is optimal).
    DeclaredSparse {
        declared: usize,
        index: FxHashMap<u64, u32>,
        numbers: Vec<u64>,
    },
}

/// The `k` of a canonical name `xk` (`k ≥ 1`), if the name is one.
fn canonical_number(name: &str) -> Option<u64> {
    let digits = name.strip_prefix('x')?;
    if digits.is_empty() || digits.starts_with('0') || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// Parses `.opb` text; `path` labels error messages.
///
/// Linear time in the text. A `#variable= N` header allocates names for `x1 … xN` only when
/// `N` is at most the text's length in bytes; a larger header (a file can mention at most
/// that many variables) keeps just the variables of the objective and records `N` in
/// [`OpbProblem::declared`].
pub fn parse_opb(text: &str, path: &str) -> Result<OpbProblem, OpbError> {
    let header = read_header(text, path)?;
    let mut names: Vec<String> = Vec::new();
    let mut naming = match header.declared {
        None => Naming::Free(FxHashMap::default()),
        Some(n) if n <= text.len() => {
            names = (1..=n).map(|k| format!("x{k}")).collect();
            Naming::Declared(n)
        }
        Some(n) => Naming::DeclaredSparse {
            declared: n,
            index: FxHashMap::default(),
            numbers: Vec::new(),
        },
    };
    let mut poly = Polynomial::new(names.len());
    // A term takes at least 4 bytes (`+1 x`); reserve for a typical 16.
    let mut batch = TermBatch::with_capacity(text.len() / 16);
    let mut it = Tokens::new(text).peekable();
    let Some(first) = it.next() else {
        return Err(OpbError::NoObjective {
            path: path.to_owned(),
        });
    };
    let sense = match first.text {
        "min:" => Sense::Minimize,
        "max:" => Sense::Maximize,
        other => {
            return Err(if other.ends_with(':') {
                syntax(
                    path,
                    &first,
                    format!("unknown objective {other:?}: expected `min:` or `max:`"),
                )
            } else {
                OpbError::Constraint {
                    path: path.to_owned(),
                    line: first.line,
                    col: first.col(),
                    found: other.to_owned(),
                }
            })
        }
    };
    let sign = if sense == Sense::Maximize { -1.0 } else { 1.0 };
    let mut closed = false;
    let mut last = first;
    let mut lits = Vec::new();
    while let Some(tok) = it.next() {
        last = tok;
        if tok.text == ";" {
            closed = true;
            break;
        }
        let coeff = if starts_number(tok.text) {
            parse_coefficient(tok.text, path, tok.line, || tok.col())?
        } else {
            return Err(syntax(
                path,
                &tok,
                format!(
                    "expected a coefficient (like +3 or -2.5) or `;`, found {:?}",
                    tok.text
                ),
            ));
        };
        lits.clear();
        while let Some(next) = it.peek() {
            if next.text == ";" || starts_number(next.text) {
                break;
            }
            let (negated, name) = match next.text.strip_prefix('~') {
                Some(n) => (true, n),
                None => (false, next.text),
            };
            if name.is_empty() || !is_identifier(name) {
                return Err(syntax(
                    path,
                    next,
                    format!("expected a literal like x3 or ~x3, found {:?}", next.text),
                ));
            }
            let unknown = |declared: usize| OpbError::UnknownVariable {
                path: path.to_owned(),
                line: next.line,
                col: next.col(),
                name: name.to_owned(),
                declared,
            };
            let var = match &mut naming {
                Naming::Free(index) => match index.get(name) {
                    Some(&v) => v,
                    None => {
                        let v = u32::try_from(names.len()).map_err(|_| {
                            syntax(path, next, "more than 2^32 variables".to_owned())
                        })?;
                        names.push(name.to_owned());
                        index.insert(name.to_owned(), v);
                        v
                    }
                },
                Naming::Declared(n) => match canonical_number(name) {
                    // k ≤ n ≤ text length, so k - 1 fits in u32 for any text we can hold.
                    Some(k) if k as usize <= *n => u32::try_from(k - 1)
                        .map_err(|_| syntax(path, next, "more than 2^32 variables".to_owned()))?,
                    _ => return Err(unknown(*n)),
                },
                Naming::DeclaredSparse {
                    declared,
                    index,
                    numbers,
                } => match canonical_number(name) {
                    Some(k) if k <= *declared as u64 => match index.get(&k) {
                        Some(&v) => v,
                        None => {
                            let v = u32::try_from(numbers.len()).map_err(|_| {
                                syntax(path, next, "more than 2^32 variables".to_owned())
                            })?;
                            numbers.push(k);
                            index.insert(k, v);
                            v
                        }
                    },
                    _ => return Err(unknown(*declared)),
                },
            };
            lits.push(if negated {
                Literal::neg(var)
            } else {
                Literal::pos(var)
            });
            it.next();
        }
        batch.push(sign * coeff, &lits);
    }
    poly.add_batch(batch);
    if !closed {
        return Err(OpbError::Syntax {
            path: path.to_owned(),
            line: last.line,
            col: last.end_col(),
            message: "objective not terminated: expected `;`".to_owned(),
        });
    }
    if let Some(extra) = it.next() {
        return Err(OpbError::Constraint {
            path: path.to_owned(),
            line: extra.line,
            col: extra.col(),
            found: extra.text.to_owned(),
        });
    }
    if let Some(c) = header.constant {
        poly.add_constant(sign * c);
    }
    if let Naming::DeclaredSparse { numbers, .. } = naming {
        // Renumber the kept variables in the order of their declared index.
        let mut order: Vec<u32> = (0..numbers.len() as u32).collect();
        order.sort_unstable_by_key(|&v| numbers[v as usize]);
        let mut new_of_old = vec![0u32; numbers.len()];
        for (new, &old) in order.iter().enumerate() {
            new_of_old[old as usize] = new as u32;
        }
        let mut sorted = Polynomial::new(numbers.len());
        sorted.add_constant(poly.constant());
        let mut batch = TermBatch::with_capacity(poly.num_terms());
        let mut mapped = Vec::new();
        for (term, coeff) in poly.terms() {
            mapped.clear();
            mapped.extend(
                term.iter()
                    .map(|l| Literal::new(new_of_old[l.var() as usize], !l.is_negated())),
            );
            batch.push(coeff, &mapped);
        }
        sorted.add_batch(batch);
        poly = sorted;
        names = order
            .iter()
            .map(|&v| format!("x{}", numbers[v as usize]))
            .collect();
    }
    poly.add_vars(names.len().saturating_sub(poly.num_vars()));
    Ok(OpbProblem {
        poly,
        names,
        sense,
        declared: header.declared,
    })
}

/// Writes a problem as `.opb` text (header, constant comment, one `min:`/`max:` line).
pub fn write_opb(problem: &OpbProblem) -> String {
    let mut out = String::new();
    let n = problem.poly.num_vars();
    let canonical = problem.names.len() == n
        && problem
            .names
            .iter()
            .enumerate()
            .all(|(i, name)| *name == format!("x{}", i + 1));
    if canonical {
        let _ = writeln!(out, "* #variable= {n} #constraint= 0");
    } else {
        // The header would declare x1 … xN; free-form names are written without it.
        let _ = writeln!(out, "* {n} variables with free-form names #constraint= 0");
    }
    let (sign, keyword) = match problem.sense {
        Sense::Minimize => (1.0, "min:"),
        Sense::Maximize => (-1.0, "max:"),
    };
    let c = sign * problem.poly.constant();
    if c != 0.0 {
        let _ = writeln!(out, "* #constant= {c}");
    }
    out.push_str(keyword);
    for (lits, a) in problem.poly.terms() {
        let a = sign * a;
        let _ = write!(out, " {}{}", if a >= 0.0 { "+" } else { "" }, a);
        for l in lits {
            let name = problem
                .names
                .get(l.var() as usize)
                .cloned()
                .unwrap_or_else(|| format!("x{}", l.var() + 1));
            let _ = write!(out, " {}{}", if l.is_negated() { "~" } else { "" }, name);
        }
    }
    out.push_str(" ;\n");
    out
}

fn header_value<'a>(comment: &'a str, key: &str) -> Option<&'a str> {
    let at = comment.find(key)?;
    comment[at + key.len()..].split_whitespace().next()
}

fn starts_number(t: &str) -> bool {
    t.starts_with(|c: char| c.is_ascii_digit() || c == '+' || c == '-' || c == '.')
}

fn is_identifier(name: &str) -> bool {
    name.starts_with(|c: char| c.is_alphabetic() || c == '_')
        && name
            .chars()
            .all(|c| c.is_alphanumeric() || matches!(c, '_' | '[' | ']' | '.' | '#' | '@'))
}

fn parse_coefficient(
    text: &str,
    path: &str,
    line: usize,
    col: impl FnOnce() -> usize,
) -> Result<f64, OpbError> {
    let t = text.strip_prefix('+').unwrap_or(text);
    let (negative, digits) = match t.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, t),
    };
    // Integers of up to 15 digits are exact in f64: read them without the float parser.
    if !digits.is_empty() && digits.len() <= 15 && digits.bytes().all(|b| b.is_ascii_digit()) {
        let v = digits
            .bytes()
            .fold(0i64, |v, b| v * 10 + i64::from(b - b'0')) as f64;
        return Ok(if negative { -v } else { v });
    }
    // A number starts with a digit or a point after its sign; this also keeps out the
    // `inf`, `infinity` and `nan` that Rust's float parser would accept.
    let parsed = if digits.starts_with(|c: char| c.is_ascii_digit() || c == '.') {
        t.parse::<f64>().ok().filter(|v| v.is_finite())
    } else {
        None
    };
    parsed.ok_or_else(|| OpbError::BadCoefficient {
        path: path.to_owned(),
        line,
        col: col(),
        text: text.to_owned(),
    })
}

fn syntax(path: &str, tok: &Token<'_>, message: String) -> OpbError {
    OpbError::Syntax {
        path: path.to_owned(),
        line: tok.line,
        col: tok.col(),
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_non_linear_objective_over_lines() {
        let p = parse_opb(
            "* #variable= 3 #constraint= 0\nmin: +3 x1 x2\n  -2 ~x3 +1 ;\n",
            "t.opb",
        )
        .unwrap();
        assert_eq!(p.names.len(), 3);
        assert_eq!(p.poly.constant(), 1.0);
        assert_eq!(p.poly.evaluate(&[true, true, false]), 2.0);
        assert_eq!(p.poly.evaluate(&[false, false, true]), 1.0);
    }

    #[test]
    fn max_objective_is_negated() {
        let p = parse_opb("max: +2 a b ;", "t").unwrap();
        assert_eq!(p.sense, Sense::Maximize);
        assert_eq!(p.poly.evaluate(&[true, true]), -2.0);
        let back = parse_opb(&write_opb(&p), "t2").unwrap();
        assert_eq!(back.sense, Sense::Maximize);
        assert_eq!(back.poly.evaluate(&[true, true]), -2.0);
    }

    #[test]
    fn round_trip_is_lossless() {
        let text = "* #variable= 4 #constraint= 0\nmin: +3 x1 x2 -2.25 ~x3 +0.1 x2 ~x4 x1 -7 ;\n";
        let p = parse_opb(text, "t").unwrap();
        let q = parse_opb(&write_opb(&p), "t").unwrap();
        for mask in 0..16u32 {
            let x: Vec<bool> = (0..4).map(|i| mask >> i & 1 == 1).collect();
            assert_eq!(p.poly.evaluate(&x), q.poly.evaluate(&x));
        }
        assert_eq!(p.names, q.names);
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = parse_opb("min: +3 x1 ;\n", "a.opb").unwrap();
        assert_eq!(e.names, ["x1"]);
        let err = parse_opb("min: +3 x1\n +nan x2 ;", "a.opb").unwrap_err();
        assert_eq!(
            err.to_string(),
            "a.opb:2:2: coefficient \"+nan\" is not a finite number"
        );
        let err = parse_opb("* #variable= 2\nmin: +1 x1 +1 x7 ;", "b.opb").unwrap_err();
        assert!(
            matches!(
                err,
                OpbError::UnknownVariable {
                    line: 2,
                    col: 15,
                    ..
                }
            ),
            "{err}"
        );
        let err = parse_opb("min: +1 x1 x2", "c.opb").unwrap_err();
        assert!(err.to_string().contains("not terminated"), "{err}");
        let err = parse_opb("min: x1 +2 ;", "d.opb").unwrap_err();
        assert!(
            matches!(
                err,
                OpbError::Syntax {
                    line: 1,
                    col: 6,
                    ..
                }
            ),
            "{err}"
        );
        let err = parse_opb("min: +1 x1 ;\n+1 x1 +1 x2 >= 1 ;", "e.opb").unwrap_err();
        assert!(matches!(err, OpbError::Constraint { line: 2, .. }), "{err}");
        let err = parse_opb("* only a comment\n", "f.opb").unwrap_err();
        assert!(matches!(err, OpbError::NoObjective { .. }));
        let err = parse_opb("min: +1e999 x1 ;", "g.opb").unwrap_err();
        assert!(matches!(err, OpbError::BadCoefficient { .. }));
        let err = parse_opb("min: +1 x$ ;", "h.opb").unwrap_err();
        assert!(matches!(err, OpbError::Syntax { col: 9, .. }), "{err}");
    }
}
