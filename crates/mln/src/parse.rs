//! The Alchemy / Tuffy / RockIt MLN language: programs, evidence and queries.
//!
//! One statement per line; `//` starts a comment, `/* … */` comments may span lines. A program holds
//! - type domains `person = { Anna, Bob }` (integer ranges `{ 1, ..., 10 }` too),
//! - predicate declarations `Friends(person, person)`; a leading `*` (Tuffy) marks a
//!   closed-world evidence predicate. A bare atom line whose predicate is not yet declared
//!   is a declaration, as in Alchemy;
//! - formulas with a weight (`1.5 Smokes(x) => Cancer(x)`), hard formulas ending in `.`,
//!   and formulas without weight (weight 0, as Alchemy reads learning input). Connectives, by
//!   increasing precedence: `<=>`, `=>`, `v`, `^`, `!`; parentheses; `EXIST x,y F` and
//!   `FORALL x F` (scope to the end of the formula); `x = y` and `x != y`. Tuffy's `@w`
//!   marks a weight that learning keeps fixed;
//! - Alchemy's `!` after a declared argument type (exactly one true atom per combination of
//!   the other arguments: two hard formulas, [`Origin::Block`]), `+x` on a variable (one
//!   formula per constant, written out by [`crate::ground::expand_per_constant`]) and `*P(…)`
//!   (the formula with every sign of the starred atoms, [`Origin::Expanded`]);
//! - `#include "file.mln"`, relative to the including file ([`read_program`]).
//!
//! Variables start with a lower-case letter; constants start with an upper-case letter or a
//! digit, or are quoted (`"Networking"`, stored without the quotes). Evidence lines are
//! ground atoms `P(A,B)` or negated `!P(A,B)`; query lines are atoms whose variables range
//! over their types (`advisedBy(x,y)`) or explicit ground atoms.
//!
//! ```
//! use mln::parse::{parse_program, Formula, Weight};
//! let p = parse_program("Smokes(person)\nCancer(person)\n1.5 Smokes(x) => Cancer(x)\n", "s.mln").unwrap();
//! assert_eq!(p.predicates.len(), 2);
//! assert_eq!(p.formulas[0].weight, Weight::Soft(1.5));
//! assert!(matches!(p.formulas[0].formula, Formula::Implies(..)));
//! ```

use std::path::Path;
use thiserror::Error;

/// Why a program, evidence or query file could not be read.
#[derive(Debug, Error)]
pub enum ParseError {
    /// The file could not be read.
    #[error("{path}: cannot read the file")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Malformed text at a position.
    #[error("{path}:{line}:{col}: {message}")]
    Syntax {
        /// The file (or a label).
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        col: usize,
        /// What was found and what was expected.
        message: String,
    },
}

/// A formula's weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Weight {
    /// A soft formula with this weight.
    Soft(f64),
    /// A hard formula (must hold).
    Hard,
}

/// A predicate, type, variable or constant name: kept inline up to 24 bytes.
///
/// A program of millions of formulas holds tens of millions of names, nearly all short
/// (`x`, `person`, `Smokes`); a `String` each was a heap object each, and those objects were
/// half the memory a large program took to read (and most of its page faults).
pub type Name = compact_str::CompactString;

/// A declared predicate.
#[derive(Debug, Clone, PartialEq)]
pub struct Predicate {
    /// Its name.
    pub name: Name,
    /// The type of each argument.
    pub arg_types: Vec<Name>,
    /// Tuffy's `*`: evidence-only, closed world.
    pub closed_world: bool,
    /// Alchemy's `!` after an argument type: the positions whose values are mutually
    /// exclusive and exhaustive (exactly one true atom per combination of the other arguments).
    pub block_args: Vec<usize>,
    /// 1-based line of the declaration.
    pub line: usize,
}

/// A declared type domain.
#[derive(Debug, Clone, PartialEq)]
pub struct TypeDecl {
    /// The type name.
    pub name: String,
    /// Its constants in declaration order.
    pub constants: Vec<String>,
    /// 1-based line.
    pub line: usize,
}

/// A term: a variable or a constant.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Term {
    /// A variable (lower-case initial).
    Var(Name),
    /// A constant (upper-case initial, digit, or quoted).
    Const(Name),
}

/// An atom `P(t1, …, tk)`; `predicate` indexes [`Program::predicates`].
#[derive(Debug, Clone, PartialEq)]
pub struct Atom {
    /// Index into the program's predicates.
    pub predicate: usize,
    /// The arguments.
    pub args: Vec<Term>,
}

/// A first-order formula.
#[derive(Debug, Clone, PartialEq)]
pub enum Formula {
    /// An atom.
    Atom(Atom),
    /// `t1 = t2`.
    Equal(Box<(Term, Term)>),
    /// Negation.
    Not(Box<Formula>),
    /// Conjunction.
    And(Vec<Formula>),
    /// Disjunction.
    Or(Vec<Formula>),
    /// Implication.
    Implies(Box<Formula>, Box<Formula>),
    /// Equivalence.
    Iff(Box<Formula>, Box<Formula>),
    /// Existential quantification.
    Exists(Vec<String>, Box<Formula>),
    /// Universal quantification.
    Forall(Vec<String>, Box<Formula>),
}

/// A formula with its weight and where it was written.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightedFormula {
    /// Soft weight or hard.
    pub weight: Weight,
    /// The formula.
    pub formula: Formula,
    /// Tuffy's `@w`: weight learning must not change this weight.
    pub fixed_weight: bool,
    /// Alchemy's `+x`: variables that get one formula (and one weight) per constant of their
    /// type; [`crate::ground::expand_per_constant`] writes those formulas out.
    pub per_constant: Vec<String>,
    /// What wrote the formula: the source text, or a construct that expands into formulas.
    pub origin: Origin,
    /// Index into [`Program::sources`] of the file the formula is in.
    pub source: usize,
    /// 1-based line in that file.
    pub line: usize,
}

/// Where a formula of a program comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// Written as it is.
    Written,
    /// One of the formulas of a line with `*` atoms or `+` variables (Alchemy expands them).
    Expanded,
    /// The exactly-one constraint of a predicate declared with `!` arguments.
    Block,
}

/// A program file and where it was included from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Source {
    /// The file's label in messages.
    pub path: String,
    /// The file and 1-based line of the `#include` that read it (`None` for the main file).
    pub included_at: Option<(usize, usize)>,
}

/// A parsed MLN program.
#[derive(Debug, Clone, Default)]
pub struct Program {
    /// Declared type domains.
    pub types: Vec<TypeDecl>,
    /// Declared predicates.
    pub predicates: Vec<Predicate>,
    /// Formulas in file order.
    pub formulas: Vec<WeightedFormula>,
    /// The file label used in messages.
    pub path: String,
    /// The main file (index 0) and the files it includes, in reading order.
    pub sources: Vec<Source>,
}

impl Program {
    /// The index of a predicate by name.
    pub fn predicate_index(&self, name: &str) -> Option<usize> {
        self.predicates.iter().position(|p| p.name == name)
    }

    /// The label of the file a formula is written in.
    pub fn file_of(&self, f: &WeightedFormula) -> &str {
        self.sources.get(f.source).map_or(&self.path, |s| &s.path)
    }

    /// A formula in the program language (parenthesised so that it reads back the same).
    pub fn formula_text(&self, f: &Formula) -> String {
        let mut out = String::new();
        self.write_formula(f, &mut out);
        out
    }

    fn write_formula(&self, f: &Formula, out: &mut String) {
        // Binding strength: a child binding no tighter than its parent gets parentheses.
        fn strength(f: &Formula) -> u8 {
            match f {
                Formula::Exists(..) | Formula::Forall(..) => 0,
                Formula::Iff(..) => 1,
                Formula::Implies(..) => 2,
                Formula::Or(..) => 3,
                Formula::And(..) => 4,
                Formula::Not(..) => 5,
                Formula::Atom(_) | Formula::Equal(..) => 6,
            }
        }
        let child = |g: &Formula, parent: u8, out: &mut String| {
            if strength(g) <= parent {
                out.push('(');
                self.write_formula(g, out);
                out.push(')');
            } else {
                self.write_formula(g, out);
            }
        };
        let join =
            |parts: &mut dyn Iterator<Item = &Formula>, op: &str, parent: u8, out: &mut String| {
                for (i, g) in parts.enumerate() {
                    if i > 0 {
                        out.push_str(op);
                    }
                    child(g, parent, out);
                }
            };
        match f {
            Formula::Atom(a) => {
                out.push_str(&self.predicates[a.predicate].name);
                out.push('(');
                for (i, t) in a.args.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    write_term(t, out);
                }
                out.push(')');
            }
            Formula::Equal(pair) => {
                let (a, b) = &**pair;
                write_term(a, out);
                out.push_str(" = ");
                write_term(b, out);
            }
            Formula::Not(g) => {
                out.push('!');
                child(g, 5, out);
            }
            Formula::And(v) => join(&mut v.iter(), " ^ ", 4, out),
            Formula::Or(v) => join(&mut v.iter(), " v ", 3, out),
            Formula::Implies(a, b) => join(&mut [&**a, &**b].into_iter(), " => ", 2, out),
            Formula::Iff(a, b) => join(&mut [&**a, &**b].into_iter(), " <=> ", 1, out),
            Formula::Exists(vars, g) | Formula::Forall(vars, g) => {
                out.push_str(if matches!(f, Formula::Exists(..)) {
                    "EXIST "
                } else {
                    "FORALL "
                });
                out.push_str(&vars.join(","));
                out.push(' ');
                self.write_formula(g, out);
            }
        }
    }
}

/// A term as written: a constant that would not read back as one is quoted.
fn write_term(t: &Term, out: &mut String) {
    match t {
        Term::Var(v) => out.push_str(v),
        Term::Const(c) => {
            let bare = c.starts_with(|ch: char| ch.is_ascii_uppercase() || ch.is_ascii_digit())
                && c.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_');
            if bare {
                out.push_str(c);
            } else {
                out.push('"');
                out.push_str(c);
                out.push('"');
            }
        }
    }
}

/// A literal of evidence: a ground atom and its truth value.
#[derive(Debug, Clone, PartialEq)]
pub struct EvidenceAtom {
    /// Index into the program's predicates.
    pub predicate: usize,
    /// Constant arguments.
    pub args: Vec<Name>,
    /// True for `P(A)`, false for `!P(A)`.
    pub value: bool,
    /// 1-based line in the evidence file.
    pub line: usize,
}

/// Reads a program file.
pub fn read_program(path: &Path) -> Result<Program, ParseError> {
    Ok(read_program_keeping(path, false)?.0)
}

/// Reads a program file, and returns with it the text of each of its files (the main file and
/// those it includes, as `Program::sources`).
pub fn read_program_sources(path: &Path) -> Result<(Program, Vec<String>), ParseError> {
    read_program_keeping(path, true)
}

/// Reads a program file, keeping its files' texts (else an empty list) when `keep`.
fn read_program_keeping(path: &Path, keep: bool) -> Result<(Program, Vec<String>), ParseError> {
    let label = path.display().to_string();
    let main = read(path)?;
    let mut included = Vec::new();
    let program = parse_program_with(&main, &label, &mut |including, name| {
        let file = Path::new(including)
            .parent()
            .unwrap_or(Path::new(""))
            .join(name);
        match std::fs::read_to_string(&file) {
            Ok(text) => {
                // Resolved in the order `Program::sources` lists the files.
                if keep {
                    included.push(text.clone());
                }
                Ok((text, file.display().to_string()))
            }
            Err(e) => Err(format!("cannot read {}: {e}", file.display())),
        }
    })?;
    let texts = if keep {
        std::iter::once(main).chain(included).collect()
    } else {
        Vec::new()
    };
    Ok((program, texts))
}

/// Reads an evidence file for a program.
pub fn read_evidence(path: &Path, program: &Program) -> Result<Vec<EvidenceAtom>, ParseError> {
    let label = path.display().to_string();
    parse_evidence(&read(path)?, &label, program)
}

/// Reads a query file: one atom per line (variables allowed).
pub fn read_query(path: &Path, program: &Program) -> Result<Vec<Atom>, ParseError> {
    let label = path.display().to_string();
    parse_query(&read(path)?, &label, program)
}

fn read(path: &Path) -> Result<String, ParseError> {
    std::fs::read_to_string(path).map_err(|source| ParseError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Lexical tokens.
#[derive(Debug, Clone, PartialEq)]
enum Tok<'s> {
    Ident(&'s str),
    Quoted(&'s str),
    Number(&'s str),
    LParen,
    RParen,
    LBrace,
    RBrace,
    Comma,
    Not,
    And,
    Implies,
    Iff,
    Eq,
    Neq,
    Dot,
    Star,
    Ellipsis,
    Plus,
    At,
}

impl Tok<'_> {
    fn describe(&self) -> String {
        match self {
            Tok::Ident(s) => format!("`{s}`"),
            Tok::Quoted(s) => format!("\"{s}\""),
            Tok::Number(s) => format!("number {s}"),
            Tok::LParen => "`(`".into(),
            Tok::RParen => "`)`".into(),
            Tok::LBrace => "`{`".into(),
            Tok::RBrace => "`}`".into(),
            Tok::Comma => "`,`".into(),
            Tok::Not => "`!`".into(),
            Tok::And => "`^`".into(),
            Tok::Implies => "`=>`".into(),
            Tok::Iff => "`<=>`".into(),
            Tok::Eq => "`=`".into(),
            Tok::Neq => "`!=`".into(),
            Tok::Dot => "`.`".into(),
            Tok::Star => "`*`".into(),
            Tok::Ellipsis => "`...`".into(),
            Tok::Plus => "`+`".into(),
            Tok::At => "`@`".into(),
        }
    }
}

/// A token and its 1-based column.
type Spanned<'s> = (Tok<'s>, usize);

/// The lexer's reusable buffer: one line's characters with their byte offsets (kept across
/// lines so that a long file allocates it once).
#[derive(Default)]
struct LexBuf {
    chars: Vec<(usize, char)>,
}

/// Splits one line (comment already removed) into tokens borrowing from the line; `out` is
/// cleared first.
fn lex<'s>(
    line: &'s str,
    path: &str,
    line_no: usize,
    buf: &mut LexBuf,
    out: &mut Vec<Spanned<'s>>,
) -> Result<(), ParseError> {
    out.clear();
    let chars = &mut buf.chars;
    chars.clear();
    chars.extend(line.char_indices());
    let chars = &*chars;
    let text = |from: usize, to: usize| -> &'s str {
        let end = chars.get(to).map_or(line.len(), |c| c.0);
        &line[chars[from].0..end]
    };
    let mut i = 0;
    let err = |col: usize, message: String| ParseError::Syntax {
        path: path.to_owned(),
        line: line_no,
        col,
        message,
    };
    while i < chars.len() {
        let c = chars[i].1;
        let col = i + 1;
        let next = chars.get(i + 1).map(|c| c.1);
        if c.is_whitespace() {
            i += 1;
            continue;
        }
        let starts_number = c.is_ascii_digit()
            || ((c == '-' || c == '+' || c == '.') && next.is_some_and(|d| d.is_ascii_digit()));
        if starts_number && !matches!(out.last(), Some((Tok::Ident(_), _))) {
            let start = i;
            i += 1;
            while i < chars.len()
                && (chars[i].1.is_ascii_alphanumeric()
                    || chars[i].1 == '.' && chars.get(i + 1).is_some_and(|d| d.1.is_ascii_digit())
                    || chars[i].1 == '_'
                    || (matches!(chars[i].1, '-' | '+') && matches!(chars[i - 1].1, 'e' | 'E')))
            {
                i += 1;
            }
            let word = text(start, i);
            // A token like `500abc` is a constant name, not a number.
            if word.parse::<f64>().is_ok() {
                out.push((Tok::Number(word), col));
            } else {
                out.push((Tok::Ident(word), col));
            }
            continue;
        }
        if c.is_alphanumeric() || c == '_' {
            let start = i;
            while i < chars.len()
                && (chars[i].1.is_alphanumeric() || matches!(chars[i].1, '_' | '-' | '\''))
            {
                i += 1;
            }
            out.push((Tok::Ident(text(start, i)), col));
            continue;
        }
        // Operators are compared in place (no allocation per token).
        let ahead = &line[chars[i].0..];
        let (tok, len) = if ahead.starts_with("<=>") {
            (Tok::Iff, 3)
        } else if ahead.starts_with("...") {
            (Tok::Ellipsis, 3)
        } else if ahead.starts_with("=>") {
            (Tok::Implies, 2)
        } else if ahead.starts_with("!=") {
            (Tok::Neq, 2)
        } else {
            match c {
                '(' => (Tok::LParen, 1),
                ')' => (Tok::RParen, 1),
                '{' => (Tok::LBrace, 1),
                '}' => (Tok::RBrace, 1),
                ',' => (Tok::Comma, 1),
                '!' => (Tok::Not, 1),
                '^' => (Tok::And, 1),
                '=' => (Tok::Eq, 1),
                '.' => (Tok::Dot, 1),
                '*' => (Tok::Star, 1),
                '+' => (Tok::Plus, 1),
                '@' => (Tok::At, 1),
                '"' => {
                    let start = i + 1;
                    let mut j = start;
                    while j < chars.len() && chars[j].1 != '"' {
                        j += 1;
                    }
                    if j >= chars.len() {
                        return Err(err(
                            col,
                            "unterminated quoted constant: expected a closing `\"`".into(),
                        ));
                    }
                    out.push((Tok::Quoted(text(start, j)), col));
                    i = j + 1;
                    continue;
                }
                ':' if next == Some('-') => {
                    return Err(err(
                        col,
                        "Tuffy's datalog rules (`head :- body`) are not supported: write the rule as a hard formula, `body => head.`".into(),
                    ))
                }
                '[' => {
                    return Err(err(
                        col,
                        "Tuffy's bracketed conditions (`[x > 1]`) are not supported".into(),
                    ))
                }
                other => return Err(err(col, format!("unexpected character {other:?}"))),
            }
        };
        out.push((tok, col));
        i += len;
    }
    Ok(())
}

/// Blanks `/* … */` block comments (outside quotes and `//` comments), keeping newlines so
/// that line and column numbers stay those of the file.
fn blank_block_comments(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.contains("/*") {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    let (mut in_block, mut in_line, mut in_quote) = (false, false, false);
    while let Some(c) = chars.next() {
        if in_block {
            if c == '*' && chars.peek() == Some(&'/') {
                chars.next();
                in_block = false;
                out.push_str("  ");
            } else {
                out.push(if c == '\n' { '\n' } else { ' ' });
            }
            continue;
        }
        match c {
            '\n' => {
                in_line = false;
                in_quote = false;
            }
            '"' if !in_line => in_quote = !in_quote,
            '/' if !in_line && !in_quote && chars.peek() == Some(&'/') => in_line = true,
            '/' if !in_line && !in_quote && chars.peek() == Some(&'*') => {
                chars.next();
                in_block = true;
                out.push_str("  ");
                continue;
            }
            _ => {}
        }
        out.push(c);
    }
    std::borrow::Cow::Owned(out)
}

/// Removes a `//` comment (outside quotes).
fn strip_comment(line: &str) -> &str {
    let mut in_quote = false;
    let bytes = line.as_bytes();
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'"' {
            in_quote = !in_quote;
        } else if !in_quote && b == b'/' && bytes.get(i + 1) == Some(&b'/') {
            return &line[..i];
        }
    }
    line
}

/// A cursor over one line's tokens.
struct Cursor<'a, 's> {
    toks: &'a [Spanned<'s>],
    pos: usize,
    path: &'a str,
    line: usize,
    line_len: usize,
    /// Nesting depth of the formula being parsed (parentheses, negations, quantifiers).
    depth: usize,
    /// A formula (where Alchemy's `+x` and `*P(…)` are allowed), not evidence or a query.
    formula: bool,
    /// Variables written `+x`, in order.
    plus_vars: Vec<String>,
    /// Atoms parsed so far (their pre-order ordinal).
    atoms: usize,
    /// Ordinals of the atoms written `*P(…)`.
    star_atoms: Vec<usize>,
}

/// Deepest formula nesting parsed; deeper input is an error, not a stack overflow.
const MAX_NESTING: usize = 200;

impl<'a, 's> Cursor<'a, 's> {
    fn new(toks: &'a [Spanned<'s>], path: &'a str, line: usize, line_len: usize) -> Self {
        Cursor {
            toks,
            pos: 0,
            path,
            line,
            line_len,
            depth: 0,
            formula: false,
            plus_vars: Vec::new(),
            atoms: 0,
            star_atoms: Vec::new(),
        }
    }
    fn peek(&self) -> Option<&'a Tok<'s>> {
        self.toks.get(self.pos).map(|(t, _)| t)
    }
    fn peek_at(&self, k: usize) -> Option<&'a Tok<'s>> {
        self.toks.get(self.pos + k).map(|(t, _)| t)
    }
    fn col(&self) -> usize {
        self.toks
            .get(self.pos)
            .map_or(self.line_len + 1, |(_, c)| *c)
    }
    fn bump(&mut self) -> Option<&'a Tok<'s>> {
        let t = self.peek();
        self.pos += 1;
        t
    }
    fn error(&self, message: String) -> ParseError {
        ParseError::Syntax {
            path: self.path.to_owned(),
            line: self.line,
            col: self.col(),
            message,
        }
    }
    fn found(&self) -> String {
        self.peek()
            .map_or("the end of the line".to_owned(), Tok::describe)
    }
    fn expect(&mut self, want: &Tok<'_>, what: &str) -> Result<(), ParseError> {
        if self.peek() == Some(want) {
            self.pos += 1;
            Ok(())
        } else {
            Err(self.error(format!("expected {what}, found {}", self.found())))
        }
    }
}

/// After a list item: `,` continues the list (true), `closer` ends it (false), anything else
/// is an error naming both.
fn list_continues(cur: &mut Cursor<'_, '_>, closer: &Tok<'_>) -> Result<bool, ParseError> {
    match cur.bump() {
        Some(Tok::Comma) => Ok(true),
        Some(t) if t == closer => Ok(false),
        _ => {
            cur.pos -= 1;
            Err(cur.error(format!(
                "expected `,` or {}, found {}",
                closer.describe(),
                cur.found()
            )))
        }
    }
}

fn is_variable(name: &str) -> bool {
    name.starts_with(|c: char| c.is_lowercase())
}

/// Parses a program's text; `path` labels messages. `#include` needs files: use
/// [`read_program`].
pub fn parse_program(text: &str, path: &str) -> Result<Program, ParseError> {
    parse_program_with(text, path, &mut |_, _| {
        Err("`#include` reads a file: read the program from a file".to_owned())
    })
}

/// Deepest chain of `#include`s followed (a file that includes itself ends here).
const MAX_INCLUDE_DEPTH: usize = 16;

/// Most files one program reads through `#include` (a file that includes itself twice would
/// otherwise be read 2^16 times).
const MAX_INCLUDED_FILES: usize = 1_000;

/// Most formulas the `*` atoms of a whole program expand into.
const MAX_STAR_FORMULAS: usize = 1_000_000;

/// Opens an included file: (including file's label, the name written) → (text, label), or
/// why not.
type Resolver<'r> = dyn FnMut(&str, &str) -> Result<(String, String), String> + 'r;

/// Parses a program whose `#include "name"` lines are read through `resolve`.
fn parse_program_with(
    text: &str,
    path: &str,
    resolve: &mut Resolver<'_>,
) -> Result<Program, ParseError> {
    let mut b = Builder {
        program: Program {
            path: path.to_owned(),
            sources: vec![Source {
                path: path.to_owned(),
                included_at: None,
            }],
            ..Program::default()
        },
        pred_index: PredIndex::default(),
        buf: LexBuf::default(),
        star_formulas: 0,
    };
    b.parse_source(text, 0, resolve, 0)?;
    b.program.predicates.shrink_to_fit();
    b.program.formulas.shrink_to_fit();
    Ok(b.program)
}

/// A program being read, with what its files share.
struct Builder {
    program: Program,
    pred_index: PredIndex,
    buf: LexBuf,
    /// Formulas written out for `*` atoms so far.
    star_formulas: usize,
}

/// Most formulas one line may expand into (`*` atoms: 2^k formulas).
const MAX_STAR_ATOMS: usize = 12;

impl Builder {
    /// Reads one file's statements into the program.
    fn parse_source(
        &mut self,
        text: &str,
        source: usize,
        resolve: &mut Resolver<'_>,
        depth: usize,
    ) -> Result<(), ParseError> {
        let path = self.program.sources[source].path.clone();
        let path = path.as_str();
        let text = &*blank_block_comments(text);
        // Every declaration and formula is one line: sized once, so a large program's lists
        // are not copied on growth (unused capacity is released at the end).
        let lines = text.bytes().filter(|&b| b == b'\n').count() + 1;
        self.program.predicates.reserve(lines);
        self.program.formulas.reserve(lines);
        let mut toks = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line_no = i + 1;
            let line = strip_comment(raw);
            if line.trim().is_empty() {
                continue;
            }
            if let Some(rest) = line.trim_start().strip_prefix("#include") {
                self.include(rest, path, line_no, line, source, resolve, depth)?;
                continue;
            }
            lex(line, path, line_no, &mut self.buf, &mut toks)?;
            let mut cur = Cursor::new(&toks, path, line_no, self.buf.chars.len());
            self.statement(&mut cur, source)?;
        }
        Ok(())
    }

    /// Reads the file an `#include` line names (`rest`: what follows `#include`).
    #[allow(clippy::too_many_arguments)]
    fn include(
        &mut self,
        rest: &str,
        path: &str,
        line_no: usize,
        line: &str,
        source: usize,
        resolve: &mut Resolver<'_>,
        depth: usize,
    ) -> Result<(), ParseError> {
        let col = line.len() - rest.len() + 1;
        let error = |message: String| ParseError::Syntax {
            path: path.to_owned(),
            line: line_no,
            col,
            message,
        };
        let name = rest.trim();
        let Some(name) = name
            .strip_prefix('"')
            .and_then(|n| n.strip_suffix('"'))
            .filter(|n| !n.is_empty() && !n.contains('"'))
        else {
            return Err(error(format!(
                "`#include` takes a quoted file name, like #include \"rules.mln\"; found `{name}`"
            )));
        };
        if self.program.sources.len() > MAX_INCLUDED_FILES {
            return Err(error(format!(
                "`#include \"{name}\"`: more than {MAX_INCLUDED_FILES} files included in all"
            )));
        }
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(error(format!(
                "`#include \"{name}\"`: includes nested deeper than {MAX_INCLUDE_DEPTH} (does a file include itself?)"
            )));
        }
        let (text, label) =
            resolve(path, name).map_err(|why| error(format!("`#include \"{name}\"`: {why}")))?;
        self.program.sources.push(Source {
            path: label,
            included_at: Some((source, line_no)),
        });
        let child = self.program.sources.len() - 1;
        self.parse_source(&text, child, resolve, depth + 1)
    }

    /// Reads one statement: a type domain, a predicate declaration or a formula.
    fn statement(&mut self, cur: &mut Cursor<'_, '_>, source: usize) -> Result<(), ParseError> {
        let line_no = cur.line;
        // Type domain: name = { … }
        if let (Some(Tok::Ident(name)), Some(Tok::Eq), Some(Tok::LBrace)) =
            (cur.peek(), cur.peek_at(1), cur.peek_at(2))
        {
            cur.pos += 3;
            let constants = parse_domain(cur)?;
            self.program.types.push(TypeDecl {
                name: (*name).to_owned(),
                constants,
                line: line_no,
            });
            return Ok(());
        }
        if let (Some(Tok::Ident(ty)), Some(Tok::Ident(f)), Some(Tok::LParen)) =
            (cur.peek(), cur.peek_at(1), cur.peek_at(2))
        {
            if !is_or(cur.peek_at(1)) {
                return Err(cur.error(format!(
                    "Alchemy's function declarations (`{ty} {f}(…)`) are not supported"
                )));
            }
        }
        // Declaration: [*] Name(type[!], …) with the name not yet declared.
        let star = cur.peek() == Some(&Tok::Star);
        let decl_at = usize::from(star);
        if let (Some(Tok::Ident(name)), Some(Tok::LParen)) =
            (cur.peek_at(decl_at), cur.peek_at(decl_at + 1))
        {
            if self
                .pred_index
                .get(name, &self.program.predicates)
                .is_none()
            {
                cur.pos += decl_at + 2;
                return self.declaration(cur, name, star, source);
            }
        }
        // Formula: [@][weight] F [.]
        let mut weight = Weight::Soft(0.0);
        // Tuffy's `@w`: a weight that learning keeps fixed; for inference it is just w.
        let fixed_weight = cur.peek() == Some(&Tok::At);
        if fixed_weight {
            cur.pos += 1;
            if !matches!(cur.peek(), Some(Tok::Number(_))) {
                return Err(cur.error(format!(
                    "expected a weight after `@`, found {}",
                    cur.found()
                )));
            }
        }
        let mut weighted = false;
        if let Some(Tok::Number(w)) = cur.peek() {
            let value: f64 = w
                .parse()
                .map_err(|_| cur.error(format!("bad weight {w}")))?;
            if !value.is_finite() {
                return Err(cur.error(format!("weight {w} is not a finite number")));
            }
            weight = Weight::Soft(value);
            weighted = true;
            cur.pos += 1;
        }
        let toks = cur.toks;
        let hard = toks.last().map(|(t, _)| t) == Some(&Tok::Dot);
        let end = if hard { toks.len() - 1 } else { toks.len() };
        let mut body = Cursor::new(&toks[..end], cur.path, line_no, cur.line_len);
        body.pos = cur.pos;
        body.formula = true;
        if hard {
            if matches!(weight, Weight::Soft(w) if w != 0.0) {
                return Err(cur.error(
                    "a formula cannot have both a weight and a trailing `.` (hard)".into(),
                ));
            }
            weight = Weight::Hard;
        }
        let formula = parse_iff(&mut body, &self.program, &self.pred_index)?;
        if body.peek().is_some() {
            return Err(body.error(format!(
                "expected a connective (^ v => <=>) or the end of the formula, found {}",
                body.found()
            )));
        }
        if star && !weighted && !hard && matches!(formula, Formula::Atom(_)) {
            // `*P(t)` alone reads as Tuffy's closed-world mark on a second declaration.
            return Err(cur.error(format!(
                "`*` marks a predicate declaration, but {} is already declared",
                match toks.get(1) {
                    Some((t, _)) => t.describe(),
                    None => "nothing".into(),
                }
            )));
        }
        if body.star_atoms.len() > MAX_STAR_ATOMS {
            return Err(cur.error(format!(
                "{} `*` atoms expand into 2^{} formulas; at most {MAX_STAR_ATOMS} are supported",
                body.star_atoms.len(),
                body.star_atoms.len()
            )));
        }
        if !body.star_atoms.is_empty() {
            self.star_formulas += 1 << body.star_atoms.len();
            if self.star_formulas > MAX_STAR_FORMULAS {
                return Err(cur.error(format!(
                    "the `*` atoms of the program expand into more than {MAX_STAR_FORMULAS} formulas"
                )));
            }
        }
        // Each `+` variable once, in first-written order (`+x … +y … +x` is x and y).
        let mut per_constant: Vec<String> = Vec::new();
        for v in std::mem::take(&mut body.plus_vars) {
            if !per_constant.contains(&v) {
                per_constant.push(v);
            }
        }
        let expanded = !body.star_atoms.is_empty() || !per_constant.is_empty();
        let origin = if expanded {
            Origin::Expanded
        } else {
            Origin::Written
        };
        let mut push = |formula: Formula| {
            self.program.formulas.push(WeightedFormula {
                weight,
                formula,
                fixed_weight,
                per_constant: per_constant.clone(),
                origin,
                source,
                line: line_no,
            })
        };
        if body.star_atoms.is_empty() {
            push(formula);
        } else {
            for mask in 0..1usize << body.star_atoms.len() {
                push(negate_starred(&formula, &body.star_atoms, mask, &mut 0));
            }
        }
        Ok(())
    }

    /// Reads a declaration's argument types (after `Name(`) and adds the predicate, with the
    /// exactly-one constraints of its `!` arguments.
    fn declaration(
        &mut self,
        cur: &mut Cursor<'_, '_>,
        name: &str,
        star: bool,
        source: usize,
    ) -> Result<(), ParseError> {
        // Sized to the line's type names (a large program holds millions of these lists).
        let types_written = cur.toks[cur.pos..]
            .iter()
            .filter(|(t, _)| matches!(t, Tok::Ident(_)))
            .count();
        let mut arg_types = Vec::with_capacity(types_written);
        let mut block_args = Vec::new();
        loop {
            match cur.bump() {
                Some(Tok::Ident(t)) => arg_types.push(Name::from(*t)),
                _ => {
                    cur.pos -= 1;
                    return Err(cur.error(format!(
                        "expected a type name in the declaration of {name}, found {}",
                        cur.found()
                    )));
                }
            }
            if cur.peek() == Some(&Tok::Not) {
                cur.pos += 1;
                block_args.push(arg_types.len() - 1);
            }
            if !list_continues(cur, &Tok::RParen)? {
                break;
            }
        }
        if cur.peek().is_some() {
            return Err(cur.error(format!(
                "unexpected {} after the declaration of {name}",
                cur.found()
            )));
        }
        let predicate = self.program.predicates.len();
        self.pred_index
            .insert(name, predicate, arg_types.len(), &self.program.predicates)
            .map_err(|why| cur.error(format!("the declaration of {name}: {why}")))?;
        self.program.predicates.push(Predicate {
            name: Name::from(name),
            arg_types,
            closed_world: star,
            block_args,
            line: cur.line,
        });
        for formula in block_constraints(&self.program.predicates[predicate], predicate) {
            self.program.formulas.push(WeightedFormula {
                weight: Weight::Hard,
                formula,
                fixed_weight: false,
                per_constant: Vec::new(),
                origin: Origin::Block,
                source,
                line: cur.line,
            });
        }
        Ok(())
    }
}

/// Alchemy's `!` arguments as hard formulas: for every combination of the other arguments,
/// at least one combination of the `!` arguments is true (`EXIST`), and no two are.
fn block_constraints(p: &Predicate, predicate: usize) -> Vec<Formula> {
    if p.block_args.is_empty() {
        return Vec::new();
    }
    let atom = |block_var: &str| {
        Formula::Atom(Atom {
            predicate,
            args: (0..p.arg_types.len())
                .map(|i| {
                    Term::Var(if p.block_args.contains(&i) {
                        compact_str::format_compact!("{block_var}{i}")
                    } else {
                        compact_str::format_compact!("u{i}")
                    })
                })
                .collect(),
        })
    };
    let vars = |block_var: &str| -> Vec<String> {
        p.block_args
            .iter()
            .map(|i| format!("{block_var}{i}"))
            .collect()
    };
    let at_least_one = Formula::Exists(vars("v"), Box::new(atom("v")));
    let mut same: Vec<Formula> = vars("v")
        .into_iter()
        .zip(vars("w"))
        .map(|(v, w)| Formula::Equal(Box::new((Term::Var(v.into()), Term::Var(w.into())))))
        .collect();
    let same = if same.len() == 1 {
        same.swap_remove(0)
    } else {
        Formula::And(same)
    };
    let at_most_one = Formula::Or(vec![
        Formula::Not(Box::new(atom("v"))),
        Formula::Not(Box::new(atom("w"))),
        same,
    ]);
    vec![at_least_one, at_most_one]
}

/// `f` with the starred atoms (by pre-order atom ordinal) whose bit in `mask` is set negated.
fn negate_starred(f: &Formula, starred: &[usize], mask: usize, ordinal: &mut usize) -> Formula {
    let mut go = |g: &Formula| negate_starred(g, starred, mask, ordinal);
    match f {
        Formula::Atom(_) => {
            let k = *ordinal;
            *ordinal += 1;
            match starred.iter().position(|&s| s == k) {
                Some(bit) if mask >> bit & 1 == 1 => Formula::Not(Box::new(f.clone())),
                _ => f.clone(),
            }
        }
        Formula::Equal(..) => f.clone(),
        Formula::Not(g) => Formula::Not(Box::new(go(g))),
        Formula::And(v) => Formula::And(v.iter().map(go).collect()),
        Formula::Or(v) => Formula::Or(v.iter().map(go).collect()),
        Formula::Implies(a, b) => {
            let a = go(a);
            Formula::Implies(Box::new(a), Box::new(go(b)))
        }
        Formula::Iff(a, b) => {
            let a = go(a);
            Formula::Iff(Box::new(a), Box::new(go(b)))
        }
        Formula::Exists(v, g) => Formula::Exists(v.clone(), Box::new(go(g))),
        Formula::Forall(v, g) => Formula::Forall(v.clone(), Box::new(go(g))),
    }
}

fn parse_domain(cur: &mut Cursor<'_, '_>) -> Result<Vec<String>, ParseError> {
    let mut out = Vec::new();
    loop {
        match cur.bump() {
            Some(Tok::Ident(c)) | Some(Tok::Quoted(c)) | Some(Tok::Number(c)) => {
                out.push((*c).to_owned())
            }
            Some(Tok::Ellipsis) => {
                // `1, ..., 10`: expand the integer range from the previous constant.
                let from = out.last().and_then(|s| s.parse::<i64>().ok());
                let Some(Tok::Comma) = cur.bump() else {
                    cur.pos -= 1;
                    return Err(cur.error("expected `,` after `...`".into()));
                };
                let to = match cur.bump() {
                    Some(Tok::Number(n)) => n.parse::<i64>().ok(),
                    _ => None,
                };
                let (Some(from), Some(to)) = (from, to) else {
                    cur.pos -= 1;
                    return Err(
                        cur.error("`...` needs integers on both sides: { 1, ..., 10 }".into())
                    );
                };
                // i128: `-9e18, ..., 9e18` must be refused, not overflow.
                if i128::from(to) - i128::from(from) > 10_000_000 {
                    return Err(cur.error(format!("range {from}..{to} is too large")));
                }
                // In i128 too: `from + 1` overflows at i64::MAX (`{ 9223372036854775807, ..., 3 }`
                // wrapped to a range of 9e18 constants in a release build).
                out.extend((i128::from(from) + 1..=i128::from(to)).map(|k| k.to_string()));
            }
            _ => {
                cur.pos -= 1;
                return Err(cur.error(format!(
                    "expected a constant in the domain, found {}",
                    cur.found()
                )));
            }
        }
        if !list_continues(cur, &Tok::RBrace)? {
            break;
        }
    }
    if cur.peek().is_some() {
        return Err(cur.error(format!("unexpected {} after the domain", cur.found())));
    }
    Ok(out)
}

/// Predicate names → (index, arity), for the readers' one lookup per atom.
///
/// Hand-written open addressing (linear probing, at most three quarters full) instead of a
/// `HashMap<Box<str>, usize>`: a slot holds the name's hash, length, first 12 bytes and the
/// predicate's arity, so looking up a name of up to 12 bytes reads one 32-byte slot and
/// nothing else, where the map read its bucket, the boxed key and then the predicate for its
/// arity: three cache misses per atom once a program's predicates outgrow the cache (the
/// parser benchmark's 2 M-predicate program read 30 % slower per byte than a small one).
/// Longer names are confirmed against the program's predicate names.
#[derive(Default)]
struct PredIndex {
    slots: Vec<PredSlot>,
    len: usize,
}

/// One slot of [`PredIndex`]; `index == u32::MAX` marks it empty.
#[derive(Clone, Copy)]
struct PredSlot {
    hash: u64,
    index: u32,
    arity: u32,
    name_len: u32,
    head: [u8; PRED_HEAD],
}

/// Bytes of a predicate name kept in its [`PredIndex`] slot.
const PRED_HEAD: usize = 12;

const EMPTY_SLOT: PredSlot = PredSlot {
    hash: 0,
    index: u32::MAX,
    arity: 0,
    name_len: 0,
    head: [0; PRED_HEAD],
};

impl PredIndex {
    /// The index of every predicate of `predicates` by name.
    fn of(predicates: &[Predicate]) -> Self {
        let mut idx = PredIndex::default();
        for (i, p) in predicates.iter().enumerate() {
            // A program's predicates have distinct names, fewer than u32::MAX of them, and
            // each fewer than u32::MAX arguments (they were read through this index).
            let _ = idx.insert(&p.name, i, p.arg_types.len(), predicates);
        }
        idx
    }

    fn hash(name: &str) -> u64 {
        use std::hash::Hasher;
        let mut h = rustc_hash::FxHasher::default();
        h.write(name.as_bytes());
        // Fibonacci mixing: the slot is taken from the top bits.
        h.finish().wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }

    fn head(name: &str) -> [u8; PRED_HEAD] {
        let mut head = [0; PRED_HEAD];
        let n = name.len().min(PRED_HEAD);
        head[..n].copy_from_slice(&name.as_bytes()[..n]);
        head
    }

    /// The slot holding `name`, or the empty slot where it would go.
    fn find(&self, name: &str, hash: u64, predicates: &[Predicate]) -> usize {
        let mask = self.slots.len() - 1;
        let mut at = (hash >> (64 - self.slots.len().trailing_zeros())) as usize;
        let head = Self::head(name);
        loop {
            let s = &self.slots[at];
            if s.index == u32::MAX {
                return at;
            }
            if s.hash == hash
                && s.name_len as usize == name.len()
                && s.head == head
                && (name.len() <= PRED_HEAD
                    || predicates.get(s.index as usize).map(|p| p.name.as_str()) == Some(name))
            {
                return at;
            }
            at = (at + 1) & mask;
        }
    }

    /// The predicate named `name` and its arity.
    fn get(&self, name: &str, predicates: &[Predicate]) -> Option<(usize, usize)> {
        if self.len == 0 {
            return None;
        }
        let s = &self.slots[self.find(name, Self::hash(name), predicates)];
        (s.index != u32::MAX).then_some((s.index as usize, s.arity as usize))
    }

    /// Adds a predicate not in the index yet; `Err` with what does not fit in a slot.
    fn insert(
        &mut self,
        name: &str,
        index: usize,
        arity: usize,
        predicates: &[Predicate],
    ) -> Result<(), &'static str> {
        let too_many = |n: usize| u32::try_from(n).ok().filter(|&n| n != u32::MAX);
        let (Some(index), Some(arity), Some(name_len)) =
            (too_many(index), too_many(arity), too_many(name.len()))
        else {
            return Err("more than 4 294 967 294 predicates, arguments or name bytes");
        };
        if 4 * (self.len + 1) > 3 * self.slots.len() {
            self.grow();
        }
        let hash = Self::hash(name);
        let at = self.find(name, hash, predicates);
        self.slots[at] = PredSlot {
            hash,
            index,
            arity,
            name_len,
            head: Self::head(name),
        };
        self.len += 1;
        Ok(())
    }

    /// Doubles the table (16 slots at first), placing every slot anew.
    fn grow(&mut self) {
        let size = (self.slots.len() * 2).max(16);
        let old = std::mem::replace(&mut self.slots, vec![EMPTY_SLOT; size]);
        let mask = size - 1;
        let shift = 64 - size.trailing_zeros();
        for s in old.into_iter().filter(|s| s.index != u32::MAX) {
            let mut at = (s.hash >> shift) as usize;
            while self.slots[at].index != u32::MAX {
                at = (at + 1) & mask;
            }
            self.slots[at] = s;
        }
    }
}

fn parse_iff(
    cur: &mut Cursor<'_, '_>,
    p: &Program,
    idx: &PredIndex,
) -> Result<Formula, ParseError> {
    let mut left = parse_implies(cur, p, idx)?;
    while cur.peek() == Some(&Tok::Iff) {
        cur.pos += 1;
        let right = parse_implies(cur, p, idx)?;
        left = Formula::Iff(Box::new(left), Box::new(right));
    }
    Ok(left)
}

fn parse_implies(
    cur: &mut Cursor<'_, '_>,
    p: &Program,
    idx: &PredIndex,
) -> Result<Formula, ParseError> {
    // `a => b => c` is `a => (b => c)`: read the chain in a loop (a long chain must not
    // recurse once per arrow), then fold from the right.
    let first = parse_or(cur, p, idx)?;
    if cur.peek() != Some(&Tok::Implies) {
        return Ok(first);
    }
    let mut operands = vec![first];
    while cur.peek() == Some(&Tok::Implies) {
        if operands.len() > MAX_NESTING {
            return Err(cur.error(format!(
                "formula nested deeper than {MAX_NESTING} levels (a chain of `=>`)"
            )));
        }
        cur.pos += 1;
        operands.push(parse_or(cur, p, idx)?);
    }
    let Some(mut f) = operands.pop() else {
        return Err(cur.error("expected a formula".into()));
    };
    while let Some(left) = operands.pop() {
        f = Formula::Implies(Box::new(left), Box::new(f));
    }
    Ok(f)
}

fn is_or(t: Option<&Tok<'_>>) -> bool {
    matches!(t, Some(Tok::Ident(s)) if *s == "v")
}

fn parse_or(cur: &mut Cursor<'_, '_>, p: &Program, idx: &PredIndex) -> Result<Formula, ParseError> {
    let first = parse_and(cur, p, idx)?;
    if !is_or(cur.peek()) {
        return Ok(first);
    }
    let mut parts = vec![first];
    while is_or(cur.peek()) {
        cur.pos += 1;
        parts.push(parse_and(cur, p, idx)?);
    }
    Ok(Formula::Or(parts))
}

fn parse_and(
    cur: &mut Cursor<'_, '_>,
    p: &Program,
    idx: &PredIndex,
) -> Result<Formula, ParseError> {
    let first = parse_unary(cur, p, idx)?;
    if cur.peek() != Some(&Tok::And) {
        return Ok(first);
    }
    let mut parts = vec![first];
    while cur.peek() == Some(&Tok::And) {
        cur.pos += 1;
        parts.push(parse_unary(cur, p, idx)?);
    }
    Ok(Formula::And(parts))
}

fn parse_unary(
    cur: &mut Cursor<'_, '_>,
    p: &Program,
    idx: &PredIndex,
) -> Result<Formula, ParseError> {
    if cur.depth >= MAX_NESTING {
        return Err(cur.error(format!(
            "formula nested deeper than {MAX_NESTING} levels (parentheses, `!`, quantifiers)"
        )));
    }
    cur.depth += 1;
    let out = parse_unary_inner(cur, p, idx);
    cur.depth -= 1;
    out
}

fn parse_unary_inner(
    cur: &mut Cursor<'_, '_>,
    p: &Program,
    idx: &PredIndex,
) -> Result<Formula, ParseError> {
    match cur.peek() {
        Some(Tok::Not) => {
            cur.pos += 1;
            Ok(Formula::Not(Box::new(parse_unary(cur, p, idx)?)))
        }
        Some(Tok::Ident(q))
            if matches!(
                q.to_ascii_uppercase().as_str(),
                "EXIST" | "EXISTS" | "FORALL"
            ) && cur.peek_at(1) != Some(&Tok::LParen) =>
        {
            let exists = q.to_ascii_uppercase().starts_with("EXIST");
            cur.pos += 1;
            let mut vars = Vec::new();
            loop {
                match cur.bump() {
                    Some(Tok::Ident(v)) if is_variable(v) => vars.push((*v).to_owned()),
                    _ => {
                        cur.pos -= 1;
                        return Err(cur.error(format!(
                            "expected a variable after the quantifier, found {}",
                            cur.found()
                        )));
                    }
                }
                if cur.peek() == Some(&Tok::Comma) {
                    cur.pos += 1;
                } else {
                    break;
                }
            }
            let body = Box::new(parse_iff(cur, p, idx)?);
            Ok(if exists {
                Formula::Exists(vars, body)
            } else {
                Formula::Forall(vars, body)
            })
        }
        _ => parse_primary(cur, p, idx),
    }
}

fn parse_term(cur: &mut Cursor<'_, '_>) -> Result<Term, ParseError> {
    if cur.peek() == Some(&Tok::Plus) {
        if !cur.formula {
            return Err(cur.error(
                "`+` (Alchemy's per-constant weights) marks a variable of a formula; it cannot be used here".into(),
            ));
        }
        cur.pos += 1;
        return match cur.bump() {
            Some(Tok::Ident(s)) if is_variable(s) => {
                cur.plus_vars.push((*s).to_owned());
                Ok(Term::Var(Name::from(*s)))
            }
            _ => {
                cur.pos -= 1;
                Err(cur.error(format!(
                    "expected a variable after `+` (per-constant weights), found {}",
                    cur.found()
                )))
            }
        };
    }
    if let (Some(Tok::Ident(f)), Some(Tok::LParen)) = (cur.peek(), cur.peek_at(1)) {
        return Err(cur.error(format!(
            "Alchemy's functions (`{f}(…)` as an argument) are not supported"
        )));
    }
    match cur.bump() {
        Some(Tok::Ident(s)) if is_variable(s) => Ok(Term::Var(Name::from(*s))),
        Some(Tok::Ident(s)) | Some(Tok::Number(s)) | Some(Tok::Quoted(s)) => {
            Ok(Term::Const(Name::from(*s)))
        }
        _ => {
            cur.pos -= 1;
            Err(cur.error(format!(
                "expected a variable or a constant, found {}",
                cur.found()
            )))
        }
    }
}

fn parse_primary(
    cur: &mut Cursor<'_, '_>,
    p: &Program,
    idx: &PredIndex,
) -> Result<Formula, ParseError> {
    match (cur.peek(), cur.peek_at(1)) {
        (Some(Tok::Star), Some(Tok::Ident(_))) if cur.formula => {
            // Alchemy's `*P(…)`: the formula is expanded with P(…) and with !P(…).
            cur.pos += 1;
            cur.star_atoms.push(cur.atoms);
            let col = cur.col();
            match parse_primary(cur, p, idx)? {
                f @ Formula::Atom(_) => Ok(f),
                _ => Err(ParseError::Syntax {
                    path: cur.path.to_owned(),
                    line: cur.line,
                    col,
                    message: "`*` must stand before an atom, like *P(x)".into(),
                }),
            }
        }
        (Some(Tok::LParen), _) => {
            cur.pos += 1;
            let f = parse_iff(cur, p, idx)?;
            cur.expect(&Tok::RParen, "`)`")?;
            Ok(f)
        }
        (Some(Tok::Ident(name)), Some(Tok::LParen)) => {
            let col = cur.col();
            let Some((pred, arity)) = idx.get(name, &p.predicates) else {
                let internal = [
                    "greaterThan",
                    "lessThan",
                    "greaterThanEq",
                    "lessThanEq",
                    "substr",
                ];
                return Err(cur.error(if internal.contains(name) {
                    format!("Alchemy's internal predicate {name} is not supported")
                } else {
                    format!(
                        "undeclared predicate {name}: declare it first, e.g. {name}(type1, type2)"
                    )
                }));
            };
            cur.pos += 2;
            let mut args = Vec::with_capacity(arity);
            if cur.peek() != Some(&Tok::RParen) {
                loop {
                    args.push(parse_term(cur)?);
                    if !list_continues(cur, &Tok::RParen)? {
                        break;
                    }
                }
            } else {
                cur.pos += 1;
            }
            if args.len() != arity {
                return Err(ParseError::Syntax {
                    path: cur.path.to_owned(),
                    line: cur.line,
                    col,
                    message: format!(
                        "{name} takes {arity} argument(s) ({}), found {}",
                        p.predicates[pred].arg_types.join(", "),
                        args.len()
                    ),
                });
            }
            cur.atoms += 1;
            Ok(Formula::Atom(Atom {
                predicate: pred,
                args,
            }))
        }
        (Some(Tok::Ident(_) | Tok::Quoted(_) | Tok::Number(_)), Some(Tok::Eq | Tok::Neq)) => {
            let a = parse_term(cur)?;
            let neq = cur.bump() == Some(&Tok::Neq);
            let b = parse_term(cur)?;
            let eq = Formula::Equal(Box::new((a, b)));
            Ok(if neq { Formula::Not(Box::new(eq)) } else { eq })
        }
        (Some(Tok::Ident(name)), _) => match idx.get(name, &p.predicates) {
            Some((pred, 0)) => {
                cur.pos += 1;
                cur.atoms += 1;
                Ok(Formula::Atom(Atom {
                    predicate: pred,
                    args: Vec::new(),
                }))
            }
            _ => Err(cur.error(format!(
                "expected an atom like {name}(x, y), found `{name}` without arguments"
            ))),
        },
        _ => Err(cur.error(format!(
            "expected an atom, `!`, `(` or a quantifier, found {}",
            cur.found()
        ))),
    }
}

/// Runs `per_line` on a cursor over each non-empty statement line of an evidence or query
/// file (comments removed), collecting the results.
fn parse_atom_lines<T>(
    text: &str,
    path: &str,
    program: &Program,
    fast: impl Fn(&str, usize, &PredIndex) -> Option<T>,
    mut per_line: impl FnMut(&mut Cursor<'_, '_>, &PredIndex) -> Result<T, ParseError>,
) -> Result<Vec<T>, ParseError> {
    let text = &*blank_block_comments(text);
    let idx = PredIndex::of(&program.predicates);
    // One entry per line at most: sized once, so a large file's output is not copied on growth.
    let mut out = Vec::with_capacity(text.bytes().filter(|&b| b == b'\n').count() + 1);
    let (mut buf, mut toks) = (LexBuf::default(), Vec::new());
    for (i, raw) in text.lines().enumerate() {
        let line = strip_comment(raw);
        if line.trim().is_empty() {
            continue;
        }
        if let Some(t) = fast(line, i + 1, &idx) {
            out.push(t);
            continue;
        }
        lex(line, path, i + 1, &mut buf, &mut toks)?;
        let mut cur = Cursor::new(&toks, path, i + 1, buf.chars.len());
        out.push(per_line(&mut cur, &idx)?);
    }
    Ok(out)
}

/// Parses one atom that must fill the rest of the line; returns it with its column.
fn parse_whole_line_atom(
    cur: &mut Cursor<'_, '_>,
    program: &Program,
    idx: &PredIndex,
    what: &str,
) -> Result<(Atom, usize), ParseError> {
    let col = cur.col();
    let Formula::Atom(atom) = parse_primary(cur, program, idx)? else {
        return Err(ParseError::Syntax {
            path: cur.path.to_owned(),
            line: cur.line,
            col,
            message: format!("expected a {what} like P(A, B)"),
        });
    };
    if cur.peek().is_some() {
        return Err(cur.error(format!("unexpected {} after the {what}", cur.found())));
    }
    Ok((atom, col))
}

/// The common evidence line `[!]Pred(Const, …)` with ASCII names (constants starting with
/// an upper-case letter), read without the lexer and its per-token allocations; `None`
/// for any other line, which then takes the general path (so errors, quoted and numeric
/// constants are read and reported as before). Tested equal to the general path.
fn fast_evidence_line(
    line: &str,
    line_no: usize,
    idx: &PredIndex,
    program: &Program,
) -> Option<EvidenceAtom> {
    let b = line.trim().as_bytes();
    let (value, mut i) = if b.first() == Some(&b'!') {
        (false, 1)
    } else {
        (true, 0)
    };
    let word = |i: &mut usize| {
        while b.get(*i).is_some_and(|c| *c == b' ' || *c == b'\t') {
            *i += 1;
        }
        let start = *i;
        while b
            .get(*i)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            *i += 1;
        }
        let end = *i;
        while b.get(*i).is_some_and(|c| *c == b' ' || *c == b'\t') {
            *i += 1;
        }
        (start < end)
            .then(|| std::str::from_utf8(&b[start..end]).ok())
            .flatten()
    };
    let name = word(&mut i)?;
    if !name.as_bytes()[0].is_ascii_alphabetic() || b.get(i) != Some(&b'(') {
        return None;
    }
    let (predicate, arity) = idx.get(name, &program.predicates)?;
    i += 1;
    let mut args = Vec::with_capacity(arity);
    loop {
        let c = word(&mut i)?;
        if !c.as_bytes()[0].is_ascii_uppercase() {
            return None;
        }
        args.push(Name::from(c));
        match b.get(i) {
            Some(b',') => i += 1,
            Some(b')') if i + 1 == b.len() => break,
            _ => return None,
        }
    }
    if args.len() != arity {
        return None;
    }
    Some(EvidenceAtom {
        predicate,
        args,
        value,
        line: line_no,
    })
}

/// Parses evidence text: ground atoms `P(A,B)` or `!P(A,B)`, one per line.
pub fn parse_evidence(
    text: &str,
    path: &str,
    program: &Program,
) -> Result<Vec<EvidenceAtom>, ParseError> {
    parse_evidence_lines(text, path, program, true)
}

/// [`parse_evidence`], with or without the fast path for common lines.
fn parse_evidence_lines(
    text: &str,
    path: &str,
    program: &Program,
    use_fast: bool,
) -> Result<Vec<EvidenceAtom>, ParseError> {
    let fast = |line: &str, n: usize, idx: &PredIndex| {
        use_fast
            .then(|| fast_evidence_line(line, n, idx, program))
            .flatten()
    };
    parse_atom_lines(text, path, program, fast, |cur, idx| {
        let value = if cur.peek() == Some(&Tok::Not) {
            cur.pos += 1;
            false
        } else {
            true
        };
        let (atom, col) = parse_whole_line_atom(cur, program, idx, "ground evidence atom")?;
        let mut args = Vec::with_capacity(atom.args.len());
        for t in atom.args {
            match t {
                Term::Const(c) => args.push(c),
                Term::Var(v) => {
                    return Err(ParseError::Syntax {
                        path: path.to_owned(),
                        line: cur.line,
                        col,
                        message: format!(
                            "evidence must be ground, but `{v}` is a variable (constants start with an upper-case letter or a digit, or are quoted)"
                        ),
                    })
                }
            }
        }
        Ok(EvidenceAtom {
            predicate: atom.predicate,
            args,
            value,
            line: cur.line,
        })
    })
}

/// Parses query text: one atom per line, variables allowed.
pub fn parse_query(text: &str, path: &str, program: &Program) -> Result<Vec<Atom>, ParseError> {
    parse_atom_lines(
        text,
        path,
        program,
        |_, _, _| None,
        |cur, idx| parse_whole_line_atom(cur, program, idx, "query atom").map(|(atom, _)| atom),
    )
}

/// Parses a `-q P1,P2` predicate list into one all-variable query atom per predicate.
pub fn parse_query_predicates(list: &str, program: &Program) -> Result<Vec<Atom>, ParseError> {
    let mut out = Vec::new();
    for (k, name) in list.split(',').map(str::trim).enumerate() {
        if name.is_empty() {
            continue;
        }
        let Some(pred) = program.predicate_index(name) else {
            return Err(ParseError::Syntax {
                path: "-q".into(),
                line: 1,
                col: k + 1,
                message: format!(
                    "unknown query predicate {name}: the program declares {}",
                    program
                        .predicates
                        .iter()
                        .map(|p| p.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        };
        let arity = program.predicates[pred].arg_types.len();
        out.push(Atom {
            predicate: pred,
            args: (0..arity)
                .map(|i| Term::Var(compact_str::format_compact!("q{i}")))
                .collect(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A large program is millions of these: short names stay inline, lists are sized to
    /// what they hold, and a formula node stays small (the MLN program reader's memory).
    #[test]
    fn a_program_holds_short_names_inline_and_lists_exactly_sized() {
        let p = parse_program(
            "Smokes(person)\nFriends(person, person)\n\
             1.5 Friends(x, y) ^ Smokes(x) => Smokes(y)\nx = y v !Smokes(Anna).\n",
            "inline.mln",
        )
        .unwrap();
        for pred in &p.predicates {
            assert!(!pred.name.is_heap_allocated(), "{}", pred.name);
            assert_eq!(
                pred.arg_types.capacity(),
                pred.arg_types.len(),
                "{}",
                pred.name
            );
        }
        let mut atoms = 0;
        fn visit(f: &Formula, seen: &mut usize) {
            match f {
                Formula::Atom(a) => {
                    *seen += 1;
                    assert_eq!(a.args.capacity(), a.args.len());
                    for t in &a.args {
                        let (Term::Var(n) | Term::Const(n)) = t;
                        assert!(!n.is_heap_allocated(), "{n}");
                    }
                }
                Formula::Equal(_) => {}
                Formula::Not(g) | Formula::Exists(_, g) | Formula::Forall(_, g) => visit(g, seen),
                Formula::And(v) | Formula::Or(v) => v.iter().for_each(|g| visit(g, seen)),
                Formula::Implies(a, b) | Formula::Iff(a, b) => {
                    visit(a, seen);
                    visit(b, seen);
                }
            }
        }
        for f in &p.formulas {
            visit(&f.formula, &mut atoms);
        }
        assert_eq!(atoms, 4);
        assert!(std::mem::size_of::<Formula>() <= 40);
    }

    #[test]
    fn predicate_index_finds_what_a_hash_map_finds() {
        // Short names, names sharing their first 12 bytes (confirmed against the program),
        // the empty name and non-ASCII; looked up among names that were never declared.
        let mut names: Vec<String> = (0..3000).map(|k| format!("P{k}")).collect();
        names.extend((0..300).map(|k| format!("SharedPrefix_{k}")));
        names.extend((0..300).map(|k| format!("SharedPrefixX{k}_long_tail")));
        names.push(String::new());
        names.push("Größe".into());
        let predicates: Vec<Predicate> = names
            .iter()
            .enumerate()
            .map(|(i, n)| Predicate {
                name: n.as_str().into(),
                arg_types: vec!["t".into(); i % 5],
                closed_world: false,
                block_args: Vec::new(),
                line: i + 1,
            })
            .collect();
        let idx = PredIndex::of(&predicates);
        let map: std::collections::HashMap<&str, (usize, usize)> = predicates
            .iter()
            .enumerate()
            .map(|(i, p)| (p.name.as_str(), (i, p.arg_types.len())))
            .collect();
        let mut probes = names.clone();
        probes.extend((0..3000).map(|k| format!("Q{k}")));
        probes.extend((0..300).map(|k| format!("SharedPrefix_{k}x")));
        probes.extend((0..300).map(|k| format!("SharedPrefixX{k}_long_tai")));
        probes.push("Größ".into());
        for name in &probes {
            assert_eq!(
                idx.get(name, &predicates),
                map.get(name.as_str()).copied(),
                "{name}"
            );
        }
        assert_eq!(PredIndex::default().get("P", &predicates), None);
    }

    #[test]
    fn issue16_deep_nesting_is_an_error_not_a_stack_overflow() {
        // Found by replaying the fuzz corpus on a 2 MB test-thread stack.
        let p = parse_program("P(a)\n", "p.mln").unwrap();
        let deep = format!("{}P(A){}\n", "(".repeat(100_000), ")".repeat(100_000));
        let err = parse_evidence(&deep, "deep.db", &p)
            .unwrap_err()
            .to_string();
        assert!(err.contains("nested deeper"), "{err}");
        let nots = format!("1 {}P(x)\n", "!".repeat(100_000));
        let err = parse_program(&format!("P(a)\n{nots}"), "n.mln")
            .unwrap_err()
            .to_string();
        assert!(err.contains("nested deeper"), "{err}");
        let chain = format!("1 P(x){}\n", " => P(x)".repeat(100_000));
        let err = parse_program(&format!("P(a)\nP(a)\n{chain}"), "c.mln").unwrap_err();
        assert!(err.to_string().contains("nested deeper"), "{err}");
        let ok = format!("1 P(x){}\n", " => P(x)".repeat(150));
        assert!(parse_program(&format!("P(a)\n{ok}"), "ok.mln").is_ok());
    }

    #[test]
    fn issue16_domain_range_spanning_all_of_i64_is_refused() {
        // Found by fuzzing: `to - from` overflowed i64.
        let text = "n = { -9000000000000000000, ..., 9000000000000000000 }\nP(n)\n";
        let err = parse_program(text, "range.mln").unwrap_err().to_string();
        assert!(err.contains("too large"), "{err}");
    }

    #[test]
    fn issue16_domain_range_from_i64_max_adds_nothing() {
        // Found by fuzzing (session 11): `from + 1` overflowed at i64::MAX; a descending or
        // empty range adds no constant, at either end of i64.
        for (text, expected) in [
            (
                "n = { 9223372036854775807, ..., 3 }\nP(n)\n",
                vec!["9223372036854775807"],
            ),
            (
                "n = { 9223372036854775806, ..., 9223372036854775807 }\nP(n)\n",
                vec!["9223372036854775806", "9223372036854775807"],
            ),
            ("n = { 5, ..., -9223372036854775808 }\nP(n)\n", vec!["5"]),
        ] {
            let p = parse_program(text, "range.mln").unwrap();
            assert_eq!(p.types[0].constants, expected, "{text}");
        }
    }

    const SMOKERS: &str = "// Evidence\n*Friends(person, person)\nSmokes(person)\nCancer(person)\n\n0.5  !Smokes(a1) v Cancer(a1)\n0.4  !Friends(a1,a2) v !Smokes(a1) v Smokes(a2)\n";

    #[test]
    fn reads_tuffy_smokers() {
        let p = parse_program(SMOKERS, "prog.mln").unwrap();
        assert_eq!(p.predicates.len(), 3);
        assert!(p.predicates[0].closed_world);
        assert!(!p.predicates[1].closed_world);
        assert_eq!(p.formulas.len(), 2);
        assert_eq!(p.formulas[1].line, 7);
        let Formula::Or(parts) = &p.formulas[1].formula else {
            panic!("expected a clause")
        };
        assert_eq!(parts.len(), 3);
        assert!(matches!(&parts[0], Formula::Not(_)));
    }

    #[test]
    fn precedence_and_connectives() {
        let p = parse_program(
            "P(t)\nQ(t)\nR(t)\n1 P(x) ^ Q(x) v R(x) => !P(x) <=> Q(x)\n",
            "p.mln",
        )
        .unwrap();
        // ((P ^ Q) v R => !P) <=> Q
        let Formula::Iff(l, _) = &p.formulas[0].formula else {
            panic!("{:?}", p.formulas[0].formula)
        };
        let Formula::Implies(ante, _) = &**l else {
            panic!()
        };
        assert!(matches!(&**ante, Formula::Or(v) if matches!(v[0], Formula::And(_))));
    }

    #[test]
    fn hard_formulas_quotes_domains_exist_and_equality() {
        let text = "person = { Anna, Bob }\nn = { 1, ..., 4 }\nF(person,person)\nS(person)\nF(x,y) ^ x != y => S(x).\n-3 S(\"Anna\")\n0 EXIST y F(x,y)\n";
        let p = parse_program(text, "p.mln").unwrap();
        assert_eq!(p.types[1].constants, ["1", "2", "3", "4"]);
        assert_eq!(p.formulas[0].weight, Weight::Hard);
        assert_eq!(p.formulas[1].weight, Weight::Soft(-3.0));
        assert!(
            matches!(&p.formulas[1].formula, Formula::Atom(a) if a.args == [Term::Const("Anna".into())])
        );
        assert!(matches!(&p.formulas[2].formula, Formula::Exists(v, _) if v == &["y".to_string()]));
    }

    #[test]
    fn errors_point_at_the_problem() {
        let e = parse_program("P(t)\n1 P(x) ^ Q(x)\n", "a.mln").unwrap_err();
        assert_eq!(
            e.to_string(),
            "a.mln:2:10: undeclared predicate Q: declare it first, e.g. Q(type1, type2)"
        );
        let e = parse_program("P(t)\n1 P(x, y)\n", "b.mln").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("b.mln:2:3: P takes 1 argument(s)"),
            "{e}"
        );
        let e = parse_program("P(t)\n1 P(x) ^\n", "c.mln").unwrap_err();
        assert!(
            e.to_string().starts_with("c.mln:2:9: expected an atom"),
            "{e}"
        );
        let e = parse_program("P(t)\n1 P(x) P(y)\n", "d.mln").unwrap_err();
        assert!(e.to_string().contains("expected a connective"), "{e}");
        let e = parse_program("P(t)\n1 P(\"x)\n", "e.mln").unwrap_err();
        assert!(e.to_string().contains("unterminated"), "{e}");
    }

    #[test]
    fn block_comments_keep_line_numbers() {
        let p = parse_program("P(t)\n/* 1 P(x)\n 2 P(y) */ 3 P(z)\n@4 P(w)\n", "b.mln").unwrap();
        assert_eq!(p.formulas.len(), 2);
        assert_eq!(p.formulas[0].weight, Weight::Soft(3.0));
        assert_eq!(p.formulas[0].line, 3);
        assert!(p.formulas[1].fixed_weight);
        let e = parse_program("P(t)\n/* x */ 1 Q(x)\n", "c.mln").unwrap_err();
        assert!(e.to_string().starts_with("c.mln:2:11:"), "{e}");
    }

    #[test]
    fn evidence_and_queries() {
        let p = parse_program(SMOKERS, "prog.mln").unwrap();
        let ev = parse_evidence("Friends(Anna, Bob)\n\n!Smokes(Gary)\n", "e.db", &p).unwrap();
        assert_eq!(ev.len(), 2);
        assert!(!ev[1].value);
        assert_eq!(ev[1].line, 3);
        let e = parse_evidence("Smokes(x)\n", "e.db", &p).unwrap_err();
        assert!(e.to_string().contains("must be ground"), "{e}");
        let e = parse_evidence("Smoke(Anna)\n", "e.db", &p).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("e.db:1:1: undeclared predicate Smoke"),
            "{e}"
        );
        let q = parse_query("Cancer(x)\n", "q.db", &p).unwrap();
        assert_eq!(q[0].predicate, 2);
        let q = parse_query_predicates("Smokes, Cancer", &p).unwrap();
        assert_eq!(q.len(), 2);
        assert!(parse_query_predicates("Cancr", &p).is_err());
    }

    #[test]
    fn fast_evidence_path_reads_every_line_as_the_general_path_does() {
        let program = parse_program(
            "Friends(person, person)\nSmokes(person)\nlower(person)\n",
            "t.mln",
        )
        .unwrap();
        let fixed = [
            "Smokes(Anna)",
            "!Friends(Anna, Bob)",
            "  Friends( Anna ,Bob )  ",
            "Friends(Anna,Bob) // c",
            "Smokes(anna)",
            "Smokes(\"a b\")",
            "Smokes(42)",
            "Smokes(A)x",
            "Smokes(A,)",
            "Smokes()",
            "Unknown(A)",
            "Friends(A)",
            "Smokes(A_1)",
            "Smokes(\u{c4}b)",
            "!!Smokes(A)",
            "! Smokes(A)",
            "Smokes (A)",
            "Smokes(A))",
            "Smokes(A) ^ Smokes(B)",
            "Smokes(\tA\t)",
            "lower(B)",
            "Smokes(1A)",
            "Smokes(A.B)",
            "Smokes(-1)",
            "Smokes(A) Smokes(B)",
            "Smokes(_A)",
        ];
        let check = |line: &str| {
            let text = format!("{line}\nSmokes(Z)\n");
            let fast = parse_evidence_lines(&text, "e.db", &program, true);
            let slow = parse_evidence_lines(&text, "e.db", &program, false);
            match (&fast, &slow) {
                (Ok(a), Ok(b)) => assert_eq!(a, b, "{line:?}"),
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{line:?}"),
                _ => panic!("{line:?}: fast {fast:?} vs general {slow:?}"),
            }
        };
        for line in fixed {
            check(line);
        }
        // Every line of up to 4 fragments drawn from the pieces above.
        let pieces = [
            "!", "Smokes", "Friends", "(", ")", ",", " ", "A", "Bob", "x", "7", "\"q\"", "_",
        ];
        let mut line = String::new();
        let n = pieces.len();
        for code in 0..(n * n * n * n) {
            line.clear();
            let mut c = code;
            for _ in 0..4 {
                line.push_str(pieces[c % n]);
                c /= n;
            }
            check(&line);
        }
        for a in ["Friends(A, B)", "Smokes(B)"] {
            for b in ["", " ", ",", ")", "(C)", "//x"] {
                check(&format!("{a}{b}"));
                check(&format!("!{a}{b}"));
            }
        }
    }
}
