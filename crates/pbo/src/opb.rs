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

use crate::polynomial::{Literal, Polynomial};
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

/// A token with its 1-based line and column.
struct Token<'a> {
    text: &'a str,
    line: usize,
    col: usize,
}

/// Parses `.opb` text; `path` labels error messages.
pub fn parse_opb(text: &str, path: &str) -> Result<OpbProblem, OpbError> {
    let mut declared: Option<usize> = None;
    let mut constant_comment: Option<f64> = None;
    let mut tokens: Vec<Token<'_>> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim_start();
        if let Some(comment) = trimmed.strip_prefix('*') {
            if let Some(n) = header_value(comment, "#variable=") {
                let n = n.parse::<usize>().map_err(|_| OpbError::Syntax {
                    path: path.to_owned(),
                    line: line_no,
                    col: line.find("#variable=").map_or(1, |c| c + 1),
                    message: format!("expected a variable count after #variable=, found {n:?}"),
                })?;
                declared = Some(n);
            }
            if let Some(c) = header_value(comment, "#constant=") {
                let col = line.find("#constant=").map_or(1, |c| c + 11);
                constant_comment = Some(parse_coefficient(c, path, line_no, col)?);
            }
            continue;
        }
        let mut rest = line;
        let mut offset = 0;
        loop {
            let start = rest.len() - rest.trim_start().len();
            rest = &rest[start..];
            offset += start;
            if rest.is_empty() {
                break;
            }
            // `;` and `:`-terminated keywords are tokens of their own.
            let len = if rest.starts_with(';') {
                1
            } else {
                rest.find(|c: char| c.is_whitespace() || c == ';')
                    .unwrap_or(rest.len())
            };
            tokens.push(Token {
                text: &rest[..len],
                line: line_no,
                col: line[..offset].chars().count() + 1,
            });
            rest = &rest[len..];
            offset += len;
        }
    }

    let mut names: Vec<String> = Vec::new();
    let mut index: FxHashMap<String, u32> = FxHashMap::default();
    if let Some(n) = declared {
        for k in 1..=n {
            index.insert(format!("x{k}"), k as u32 - 1);
            names.push(format!("x{k}"));
        }
    }
    let mut poly = Polynomial::new(names.len());
    let mut it = tokens.iter().peekable();
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
                    first,
                    format!("unknown objective {other:?}: expected `min:` or `max:`"),
                )
            } else {
                OpbError::Constraint {
                    path: path.to_owned(),
                    line: first.line,
                    col: first.col,
                    found: other.to_owned(),
                }
            })
        }
    };
    let sign = if sense == Sense::Maximize { -1.0 } else { 1.0 };
    let mut closed = false;
    while let Some(tok) = it.next() {
        if tok.text == ";" {
            closed = true;
            break;
        }
        let coeff = if starts_number(tok.text) {
            parse_coefficient(tok.text, path, tok.line, tok.col)?
        } else {
            return Err(syntax(
                path,
                tok,
                format!(
                    "expected a coefficient (like +3 or -2.5) or `;`, found {:?}",
                    tok.text
                ),
            ));
        };
        let mut lits = Vec::new();
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
            let var = match index.get(name) {
                Some(&v) => v,
                None => {
                    if let Some(n) = declared {
                        return Err(OpbError::UnknownVariable {
                            path: path.to_owned(),
                            line: next.line,
                            col: next.col,
                            name: name.to_owned(),
                            declared: n,
                        });
                    }
                    let v = names.len() as u32;
                    names.push(name.to_owned());
                    index.insert(name.to_owned(), v);
                    v
                }
            };
            lits.push(if negated {
                Literal::neg(var)
            } else {
                Literal::pos(var)
            });
            it.next();
        }
        poly.add_term(sign * coeff, &lits);
    }
    if !closed {
        let (line, col) = tokens
            .last()
            .map_or((1, 1), |t| (t.line, t.col + t.text.len()));
        return Err(OpbError::Syntax {
            path: path.to_owned(),
            line,
            col,
            message: "objective not terminated: expected `;`".to_owned(),
        });
    }
    if let Some(extra) = it.next() {
        return Err(OpbError::Constraint {
            path: path.to_owned(),
            line: extra.line,
            col: extra.col,
            found: extra.text.to_owned(),
        });
    }
    if let Some(c) = constant_comment {
        poly.add_constant(sign * c);
    }
    poly.add_vars(names.len().saturating_sub(poly.num_vars()));
    Ok(OpbProblem { poly, names, sense })
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

fn parse_coefficient(text: &str, path: &str, line: usize, col: usize) -> Result<f64, OpbError> {
    let bad = || OpbError::BadCoefficient {
        path: path.to_owned(),
        line,
        col,
        text: text.to_owned(),
    };
    let t = text.strip_prefix('+').unwrap_or(text);
    let lower = t.to_ascii_lowercase();
    if lower.contains("nan") || lower.contains("inf") {
        return Err(bad());
    }
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(bad()),
    }
}

fn syntax(path: &str, tok: &Token<'_>, message: String) -> OpbError {
    OpbError::Syntax {
        path: path.to_owned(),
        line: tok.line,
        col: tok.col,
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
