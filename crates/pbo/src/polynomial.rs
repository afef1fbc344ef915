//! Multilinear pseudo-Boolean functions over literals: f(x) = c + Σₖ aₖ Πᵢ lᵢ.
//!
//! A literal is a variable x = x⁽¹⁾ or its complement x̄ = x⁽⁰⁾ = 1 − x. A [`Polynomial`]
//! keeps one term per distinct literal set (identical monomials are merged through a hash
//! of the sorted literal set, or, for a [`TermBatch`] of many terms at once, by a radix sort
//! that reads memory in order: a file reader's million-term batch then costs no cache miss
//! per term), a constant, and the number of variables. It converts to the
//! *multinomial* form (positive literals only) and to a *posiform* (every coefficient ≥ 0
//! except the constant, which is then a lower bound on the minimum), substitutes fixed
//! variables, and evaluates assignments. See Boros & Hammer, "Pseudo-Boolean
//! optimization", Discrete Applied Mathematics 123 (2002), doi:10.1016/S0166-218X(01)00341-9.
//!
//! ```
//! use pbo::polynomial::{Literal, Polynomial};
//! // f = 2 + 3·x0·x1 − 2·x̄2
//! let mut f = Polynomial::new(3);
//! f.add_constant(2.0);
//! f.add_term(3.0, &[Literal::pos(0), Literal::pos(1)]);
//! f.add_term(-2.0, &[Literal::neg(2)]);
//! assert_eq!(f.evaluate(&[true, true, false]), 3.0);
//! assert_eq!(f.degree(), 2);
//! let p = f.to_posiform();
//! assert!(p.terms().all(|(_, a)| a >= 0.0));
//! assert!(p.constant() <= 0.0); // a lower bound on min f = 0
//! ```

use rustc_hash::FxHashMap;

/// Terms with more negated literals than this are not expanded into multinomial form
/// (2ᵏ monomials).
pub const MAX_MULTINOMIAL_NEGATED: usize = 24;

/// A term too long to expand into multinomial form.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("a term with {negated} negated literals (degree {degree}) would expand into 2^{negated} monomials; at most {MAX_MULTINOMIAL_NEGATED} negated literals can be expanded")]
pub struct ExpansionError {
    /// Negated literals in the offending term.
    pub negated: usize,
    /// Its degree.
    pub degree: usize,
}

/// A literal: a variable index with a polarity (x or x̄ = 1 − x).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Literal(u32);

impl Literal {
    /// The positive literal x⁽¹⁾ = x of variable `var`.
    #[inline]
    pub fn pos(var: u32) -> Literal {
        Literal(var << 1)
    }

    /// The negative literal x⁽⁰⁾ = 1 − x of variable `var`.
    #[inline]
    pub fn neg(var: u32) -> Literal {
        Literal((var << 1) | 1)
    }

    /// The literal of `var` that is true when the variable equals `value`.
    #[inline]
    pub fn new(var: u32, value: bool) -> Literal {
        if value {
            Literal::pos(var)
        } else {
            Literal::neg(var)
        }
    }

    /// The variable index.
    #[inline]
    pub fn var(self) -> u32 {
        self.0 >> 1
    }

    /// Whether this is the complemented literal x̄.
    #[inline]
    pub fn is_negated(self) -> bool {
        self.0 & 1 == 1
    }

    /// The complementary literal.
    #[inline]
    pub fn complement(self) -> Literal {
        Literal(self.0 ^ 1)
    }

    /// The literal's value (0 or 1) when its variable takes `value`.
    #[inline]
    pub fn eval(self, value: bool) -> bool {
        value != self.is_negated()
    }

    /// +1 for x, −1 for x̄: the sign this literal contributes to multinomial coefficients.
    #[inline]
    pub fn sign(self) -> f64 {
        if self.is_negated() {
            -1.0
        } else {
            1.0
        }
    }
}

impl std::fmt::Display for Literal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.is_negated() {
            write!(f, "~x{}", self.var())
        } else {
            write!(f, "x{}", self.var())
        }
    }
}

/// One monomial a·Π lᵢ of a [`Polynomial`]: literals sorted, on distinct variables.
#[derive(Debug, Clone, PartialEq)]
struct Term {
    literals: Box<[Literal]>,
    coeff: f64,
}

/// A multilinear pseudo-Boolean function c + Σₖ aₖ Πᵢ lᵢ over `num_vars` variables.
#[derive(Debug, Clone, Default)]
pub struct Polynomial {
    num_vars: usize,
    constant: f64,
    terms: Vec<Term>,
    /// Looks up `terms[..indexed]`; the rest (added by [`Polynomial::add_batch`]) is indexed
    /// on the next single-term addition.
    index: TermIndex,
    indexed: usize,
}

/// Monomial → position in `Polynomial::terms`. Monomials of one or two literals (the bulk
/// of every real function) are keyed by their packed literals, so a lookup reads no
/// pointer; longer ones by their literal slice.
#[derive(Debug, Clone, Default)]
struct TermIndex {
    short: FxHashMap<u64, usize>,
    long: FxHashMap<Box<[Literal]>, usize>,
}

impl TermIndex {
    /// The packed key of a sorted monomial of one or two literals. A single literal `a`
    /// is `(u32::MAX, a)`: no sorted pair starts with the largest literal.
    fn short_key(lits: &[Literal]) -> Option<u64> {
        match lits {
            [a] => Some((u64::from(u32::MAX) << 32) | u64::from(a.0)),
            [a, b] => Some((u64::from(a.0) << 32) | u64::from(b.0)),
            _ => None,
        }
    }

    fn get(&self, lits: &[Literal]) -> Option<usize> {
        match Self::short_key(lits) {
            Some(k) => self.short.get(&k).copied(),
            None => self.long.get(lits).copied(),
        }
    }

    fn insert(&mut self, lits: &[Literal], pos: usize) {
        match Self::short_key(lits) {
            Some(k) => {
                self.short.insert(k, pos);
            }
            None => {
                self.long.insert(lits.into(), pos);
            }
        }
    }

    fn reserve(&mut self, additional: usize) {
        self.short.reserve(additional);
    }

    fn clear(&mut self) {
        self.short.clear();
        self.long.clear();
    }
}

/// Sorts literals, drops repeats (l·l = l); returns `None` if x·x̄ makes the product zero.
fn normalize(literals: &[Literal]) -> Option<Vec<Literal>> {
    let mut lits = literals.to_vec();
    let n = normalize_in_place(&mut lits)?;
    lits.truncate(n);
    Some(lits)
}

/// [`normalize`] in place: sorts `lits`, moves the distinct literals to the front and
/// returns their number, or `None` if x·x̄ makes the product zero.
fn normalize_in_place(lits: &mut [Literal]) -> Option<usize> {
    lits.sort_unstable();
    let mut n = 0;
    for i in 0..lits.len() {
        if n > 0 && lits[n - 1] == lits[i] {
            continue;
        }
        if n > 0 && lits[n - 1].var() == lits[i].var() {
            return None;
        }
        lits[n] = lits[i];
        n += 1;
    }
    Some(n)
}

/// Many terms to add at once with [`Polynomial::add_batch`] (a file reader's objective).
#[derive(Debug, Clone, Default)]
pub struct TermBatch {
    constants: Vec<f64>,
    num_vars: usize,
    terms: Vec<Term>,
    /// (packed literals, position in `terms`) of the monomials of one or two literals.
    short: Vec<(u64, usize)>,
    /// Positions in `terms` of the longer monomials.
    long: Vec<usize>,
}

impl TermBatch {
    /// An empty batch with room for `terms` terms.
    pub fn with_capacity(terms: usize) -> TermBatch {
        TermBatch {
            terms: Vec::with_capacity(terms),
            short: Vec::with_capacity(terms),
            ..TermBatch::default()
        }
    }

    /// Appends `coeff · Π literals`, read as [`Polynomial::add_term`] reads it.
    pub fn push(&mut self, coeff: f64, literals: &[Literal]) {
        if coeff == 0.0 {
            return;
        }
        let mut buf = [Literal(0); 4];
        let lits: std::borrow::Cow<'_, [Literal]> = if literals.len() <= 4 {
            let lits = &mut buf[..literals.len()];
            lits.copy_from_slice(literals);
            match normalize_in_place(lits) {
                Some(n) => std::borrow::Cow::Borrowed(&buf[..n]),
                None => return,
            }
        } else {
            match normalize(literals) {
                Some(l) => std::borrow::Cow::Owned(l),
                None => return,
            }
        };
        let Some(last) = lits.last() else {
            self.constants.push(coeff);
            return;
        };
        self.num_vars = self.num_vars.max(last.var() as usize + 1);
        let pos = self.terms.len();
        match TermIndex::short_key(&lits) {
            Some(key) => self.short.push((key, pos)),
            None => self.long.push(pos),
        }
        self.terms.push(Term {
            literals: lits.as_ref().into(),
            coeff,
        });
    }

    /// Number of terms pushed (constants and vanishing products not counted).
    pub fn len(&self) -> usize {
        self.terms.len()
    }

    /// Whether no term was pushed.
    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }
}

/// Stable LSD radix sort of (key, payload) pairs by key, one pass per byte in which the keys
/// differ.
fn radix_sort_by_key(mut items: Vec<(u64, usize)>) -> Vec<(u64, usize)> {
    let mut counts = vec![[0usize; 256]; 8];
    for &(key, _) in &items {
        for (byte, c) in counts.iter_mut().enumerate() {
            c[(key >> (8 * byte)) as usize & 0xff] += 1;
        }
    }
    let mut scratch = vec![(0u64, 0usize); items.len()];
    for (byte, c) in counts.iter().enumerate() {
        if c.contains(&items.len()) {
            continue; // every key has the same byte here
        }
        let mut start = [0usize; 256];
        let mut sum = 0;
        for (s, &n) in start.iter_mut().zip(c.iter()) {
            *s = sum;
            sum += n;
        }
        for &item in &items {
            let b = (item.0 >> (8 * byte)) as usize & 0xff;
            scratch[start[b]] = item;
            start[b] += 1;
        }
        std::mem::swap(&mut items, &mut scratch);
    }
    items
}

impl Polynomial {
    /// The zero function over `num_vars` variables.
    pub fn new(num_vars: usize) -> Polynomial {
        Polynomial {
            num_vars,
            ..Polynomial::default()
        }
    }

    /// Number of variables (indices `0..num_vars`); not all need to occur in a term.
    pub fn num_vars(&self) -> usize {
        self.num_vars
    }

    /// Adds fresh variables and returns the index of the first one.
    pub fn add_vars(&mut self, count: usize) -> u32 {
        let first = self.num_vars as u32;
        self.num_vars += count;
        first
    }

    /// The constant term.
    pub fn constant(&self) -> f64 {
        self.constant
    }

    /// Adds `c` to the constant term.
    pub fn add_constant(&mut self, c: f64) {
        self.constant += c;
    }

    /// Adds `coeff · Π literals`, merging with an existing identical monomial.
    ///
    /// Literals may come in any order and repeat; a product containing x and x̄ is zero and
    /// is dropped; the empty product adds to the constant. Variables beyond `num_vars`
    /// grow the variable count.
    pub fn add_term(&mut self, coeff: f64, literals: &[Literal]) {
        if coeff == 0.0 {
            return;
        }
        // Up to four literals are sorted on the stack: the lookup of an existing monomial
        // allocates nothing (file readers add millions of short terms).
        if literals.len() <= 4 {
            let mut buf = [Literal(0); 4];
            let lits = &mut buf[..literals.len()];
            lits.copy_from_slice(literals);
            if let Some(n) = normalize_in_place(lits) {
                self.add_sorted_slice(coeff, &buf[..n]);
            }
            return;
        }
        let Some(lits) = normalize(literals) else {
            return;
        };
        self.add_normalized(coeff, lits);
    }

    /// Reserves room for `additional` more terms.
    pub fn reserve_terms(&mut self, additional: usize) {
        self.terms.reserve(additional);
        self.index.reserve(additional);
    }

    /// Adds a term given as sorted literals on distinct variables, allocating only when
    /// the monomial is new.
    fn add_sorted_slice(&mut self, coeff: f64, lits: &[Literal]) {
        let Some(last) = lits.last() else {
            self.constant += coeff;
            return;
        };
        self.num_vars = self.num_vars.max(last.var() as usize + 1);
        self.sync_index();
        if let Some(pos) = self.index.get(lits) {
            self.terms[pos].coeff += coeff;
        } else {
            self.index.insert(lits, self.terms.len());
            self.terms.push(Term {
                literals: lits.into(),
                coeff,
            });
            self.indexed = self.terms.len();
        }
    }

    /// Indexes the terms a batch appended without indexing them.
    fn sync_index(&mut self) {
        if self.indexed == self.terms.len() {
            return;
        }
        self.index.reserve(self.terms.len() - self.indexed);
        for (i, t) in self.terms.iter().enumerate().skip(self.indexed) {
            self.index.insert(&t.literals, i);
        }
        self.indexed = self.terms.len();
    }

    /// Adds every term of `batch`: the same function, terms and term order as
    /// [`Polynomial::add_term`] on each in turn.
    ///
    /// Into a zero polynomial, repeated monomials are merged by a stable radix sort of their
    /// packed literals (linear time, memory read in order) instead of one hash lookup per
    /// term, and the lookup index is built only when a single term is added later.
    pub fn add_batch(&mut self, batch: TermBatch) {
        let TermBatch {
            constants,
            num_vars,
            mut terms,
            short,
            long,
        } = batch;
        // The constant is summed in arrival order, as add_term sums it.
        for c in constants {
            self.constant += c;
        }
        if !self.terms.is_empty() {
            for t in terms {
                self.add_sorted_slice(t.coeff, &t.literals);
            }
            return;
        }
        self.num_vars = self.num_vars.max(num_vars);
        let mut alive = vec![true; terms.len()];
        // Short monomials: equal keys are adjacent after the sort, in arrival order (the
        // sort is stable), so each run adds into its first term in the order add_term would.
        let sorted = radix_sort_by_key(short);
        let mut i = 0;
        while i < sorted.len() {
            let (key, first) = sorted[i];
            let mut j = i + 1;
            while j < sorted.len() && sorted[j].0 == key {
                let other = sorted[j].1;
                terms[first].coeff += terms[other].coeff;
                alive[other] = false;
                j += 1;
            }
            i = j;
        }
        // Longer monomials (rare in files): hashed, first occurrence kept.
        let mut merges = Vec::new();
        {
            let mut first_of: FxHashMap<&[Literal], usize> = FxHashMap::default();
            for &pos in &long {
                match first_of.entry(&terms[pos].literals) {
                    std::collections::hash_map::Entry::Occupied(e) => merges.push((*e.get(), pos)),
                    std::collections::hash_map::Entry::Vacant(e) => {
                        e.insert(pos);
                    }
                }
            }
        }
        for (first, other) in merges {
            terms[first].coeff += terms[other].coeff;
            alive[other] = false;
        }
        let mut k = 0;
        terms.retain(|_| {
            k += 1;
            alive[k - 1]
        });
        self.terms = terms;
        self.index.clear();
        self.indexed = 0;
    }

    /// Adds a term whose literals are already sorted and on distinct variables.
    fn add_normalized(&mut self, coeff: f64, lits: Vec<Literal>) {
        self.add_sorted_slice(coeff, &lits);
    }

    /// The non-zero terms as (sorted literals, coefficient), in insertion order.
    pub fn terms(&self) -> impl Iterator<Item = (&[Literal], f64)> + '_ {
        self.terms
            .iter()
            .filter(|t| t.coeff != 0.0)
            .map(|t| (&*t.literals, t.coeff))
    }

    /// The coefficient of the monomial with exactly these literals (0 if absent).
    pub fn coefficient(&self, literals: &[Literal]) -> f64 {
        match normalize(literals) {
            Some(lits) if lits.is_empty() => self.constant,
            Some(lits) => self
                .index
                .get(lits.as_slice())
                .or_else(|| {
                    // Terms a batch added are not indexed yet: scanned (callers that add
                    // single terms index them first).
                    (self.indexed..self.terms.len()).find(|&i| *self.terms[i].literals == *lits)
                })
                .map_or(0.0, |i| self.terms[i].coeff),
            None => 0.0,
        }
    }

    /// Number of non-zero terms (the constant not counted).
    pub fn num_terms(&self) -> usize {
        self.terms.iter().filter(|t| t.coeff != 0.0).count()
    }

    /// Largest number of literals in a non-zero term (0 for a constant function).
    pub fn degree(&self) -> usize {
        self.terms().map(|(l, _)| l.len()).max().unwrap_or(0)
    }

    /// Number of non-zero terms of degree ≥ 3.
    pub fn num_higher_order_terms(&self) -> usize {
        self.terms().filter(|(l, _)| l.len() > 2).count()
    }

    /// Whether each variable occurs in some non-zero term.
    pub fn occurring_vars(&self) -> Vec<bool> {
        let mut occ = vec![false; self.num_vars];
        for (lits, _) in self.terms() {
            for l in lits {
                occ[l.var() as usize] = true;
            }
        }
        occ
    }

    /// The value at an assignment; `x[i]` is variable i (missing variables count as 0).
    pub fn evaluate(&self, x: &[bool]) -> f64 {
        self.constant
            + self
                .terms()
                .filter(|(lits, _)| {
                    lits.iter()
                        .all(|l| l.eval(x.get(l.var() as usize).copied().unwrap_or(false)))
                })
                .map(|(_, a)| a)
                .sum::<f64>()
    }

    /// The same function with positive literals only (x̄ expanded as 1 − x).
    ///
    /// A term with k negated literals expands into 2ᵏ monomials before merging, so terms
    /// with more than [`MAX_MULTINOMIAL_NEGATED`] negated literals are refused.
    pub fn to_multinomial(&self) -> Result<Polynomial, ExpansionError> {
        if let Some((lits, _)) = self
            .terms()
            .find(|(l, _)| l.iter().filter(|x| x.is_negated()).count() > MAX_MULTINOMIAL_NEGATED)
        {
            return Err(ExpansionError {
                negated: lits.iter().filter(|x| x.is_negated()).count(),
                degree: lits.len(),
            });
        }
        Ok(self.to_multinomial_partial(MAX_MULTINOMIAL_NEGATED))
    }

    /// The same function with every term of at most `max_negated` negated literals expanded
    /// into positive literals; longer terms stay as they are (a mixed form).
    pub fn to_multinomial_partial(&self, max_negated: usize) -> Polynomial {
        let mut out = Polynomial::new(self.num_vars);
        out.constant = self.constant;
        for (lits, a) in self.terms() {
            let negated: Vec<usize> = (0..lits.len()).filter(|&i| lits[i].is_negated()).collect();
            let k = negated.len();
            if k > max_negated.min(MAX_MULTINOMIAL_NEGATED) {
                out.add_normalized(a, lits.to_vec());
                continue;
            }
            let fixed: Vec<Literal> = lits.iter().copied().filter(|l| !l.is_negated()).collect();
            // Π_{fixed} x · Π_{negated} (1 − x) = Σ_{S ⊆ negated} (−1)^{|S|} Π_{fixed ∪ S} x
            for mask in 0u64..(1u64 << k) {
                let mut mono = fixed.clone();
                for (bit, &i) in negated.iter().enumerate() {
                    if mask >> bit & 1 == 1 {
                        mono.push(Literal::pos(lits[i].var()));
                    }
                }
                mono.sort_unstable();
                let sign = if mask.count_ones() % 2 == 1 {
                    -1.0
                } else {
                    1.0
                };
                out.add_normalized(sign * a, mono);
            }
        }
        out.simplify(0.0);
        out
    }

    /// An equal function whose terms all have coefficients > 0; the constant is then a lower
    /// bound on the minimum.
    ///
    /// A negative term a·l₁⋯lₖ is rewritten as a + Σⱼ (−a)·l₁⋯lⱼ₋₁·l̄ⱼ (using
    /// 1 − Π l = Σⱼ Π_{i<j} lᵢ · l̄ⱼ), whose coefficients are all positive.
    pub fn to_posiform(&self) -> Polynomial {
        let mut out = Polynomial::new(self.num_vars);
        out.constant = self.constant;
        for (lits, a) in self.terms() {
            if a > 0.0 {
                out.add_normalized(a, lits.to_vec());
            } else {
                out.constant += a;
                for j in 0..lits.len() {
                    let mut mono: Vec<Literal> = lits[..j].to_vec();
                    mono.push(lits[j].complement());
                    mono.sort_unstable();
                    out.add_normalized(-a, mono);
                }
            }
        }
        out.simplify(0.0);
        out
    }

    /// The function with some variables fixed: `fixed[i] = Some(v)` substitutes x_i = v.
    ///
    /// A literal that becomes 1 leaves its term; a literal that becomes 0 removes the term.
    /// Fixed variables no longer occur; the variable numbering is unchanged.
    pub fn fix(&self, fixed: &[Option<bool>]) -> Polynomial {
        let mut out = Polynomial::new(self.num_vars);
        out.constant = self.constant;
        'terms: for (lits, a) in self.terms() {
            let mut rest = Vec::with_capacity(lits.len());
            for &l in lits {
                match fixed.get(l.var() as usize).copied().flatten() {
                    Some(v) if l.eval(v) => {}
                    Some(_) => continue 'terms,
                    None => rest.push(l),
                }
            }
            out.add_normalized(a, rest);
        }
        out.simplify(0.0);
        out
    }

    /// Removes terms with |coefficient| ≤ `tolerance` (use 0.0 to drop exact zeros only).
    pub fn simplify(&mut self, tolerance: f64) {
        if self.terms.iter().all(|t| t.coeff.abs() > tolerance) {
            return;
        }
        self.terms.retain(|t| t.coeff.abs() > tolerance);
        self.index.clear();
        self.indexed = 0;
    }

    /// The exact minimum and a minimiser by enumerating all 2ⁿ assignments (n ≤ 25).
    ///
    /// For tests and tiny problems only.
    pub fn brute_force_minimum(&self) -> (f64, Vec<bool>) {
        assert!(
            self.num_vars <= 25,
            "brute force over {} variables",
            self.num_vars
        );
        let n = self.num_vars;
        let mut best = (f64::INFINITY, vec![false; n]);
        let mut x = vec![false; n];
        for mask in 0u64..(1u64 << n) {
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = mask >> i & 1 == 1;
            }
            let v = self.evaluate(&x);
            if v < best.0 {
                best = (v, x.clone());
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn all_assignments(n: usize) -> impl Iterator<Item = Vec<bool>> {
        (0u64..(1u64 << n)).map(move |m| (0..n).map(|i| m >> i & 1 == 1).collect())
    }

    #[test]
    fn merges_identical_monomials_in_any_order() {
        let mut f = Polynomial::new(3);
        f.add_term(1.0, &[Literal::pos(2), Literal::neg(0)]);
        f.add_term(2.5, &[Literal::neg(0), Literal::pos(2)]);
        assert_eq!(f.num_terms(), 1);
        assert_eq!(f.coefficient(&[Literal::neg(0), Literal::pos(2)]), 3.5);
    }

    #[test]
    fn contradictory_product_vanishes_and_repeats_collapse() {
        let mut f = Polynomial::new(2);
        f.add_term(5.0, &[Literal::pos(0), Literal::neg(0)]);
        assert_eq!(f.num_terms(), 0);
        f.add_term(2.0, &[Literal::pos(1), Literal::pos(1)]);
        assert_eq!(f.coefficient(&[Literal::pos(1)]), 2.0);
        assert_eq!(f.degree(), 1);
    }

    #[test]
    fn thesis_example_3_2_2_smokers() {
        // φ = 1 − s_y + f·s_x·s_y (variables s_x = 0, s_y = 1, f = 2), values by hand.
        let mut phi = Polynomial::new(3);
        phi.add_constant(1.0);
        phi.add_term(-1.0, &[Literal::pos(1)]);
        phi.add_term(1.0, &[Literal::pos(2), Literal::pos(0), Literal::pos(1)]);
        assert_eq!(phi.evaluate(&[false, false, false]), 1.0);
        assert_eq!(phi.evaluate(&[true, true, true]), 1.0);
        assert_eq!(phi.evaluate(&[false, true, false]), 0.0);
        assert_eq!(phi.degree(), 3);
    }

    #[test]
    fn long_negated_terms_are_refused_or_kept() {
        // The EXIST clauses of LP have ~70 negated literals: 2^70 monomials.
        let mut f = Polynomial::new(70);
        let lits: Vec<Literal> = (0..70).map(Literal::neg).collect();
        f.add_term(-2.5, &lits);
        let e = f.to_multinomial().unwrap_err();
        assert_eq!(e.negated, 70);
        let p = f.to_multinomial_partial(12);
        assert_eq!(p.num_terms(), 1);
        assert_eq!(p.evaluate(&[false; 70]), -2.5);
    }

    #[test]
    fn fixing_substitutes_and_simplifies() {
        // f = 3·x0·x̄1 + 2·x1·x2 − x2
        let mut f = Polynomial::new(3);
        f.add_term(3.0, &[Literal::pos(0), Literal::neg(1)]);
        f.add_term(2.0, &[Literal::pos(1), Literal::pos(2)]);
        f.add_term(-1.0, &[Literal::pos(2)]);
        let g = f.fix(&[None, Some(true), None]);
        // x1 = 1: the first term vanishes, the second becomes 2·x2: g = x2.
        assert_eq!(g.num_terms(), 1);
        assert_eq!(g.coefficient(&[Literal::pos(2)]), 1.0);
        let h = f.fix(&[Some(true), Some(false), Some(true)]);
        assert_eq!(h.num_terms(), 0);
        assert_eq!(h.constant(), 2.0);
    }

    fn arb_polynomial(max_vars: usize, max_degree: usize) -> impl Strategy<Value = Polynomial> {
        (1..=max_vars).prop_flat_map(move |n| {
            let term = (
                proptest::collection::vec((0..n as u32, any::<bool>()), 1..=max_degree),
                -10i32..=10,
            );
            (Just(n), -5i32..=5, proptest::collection::vec(term, 0..12)).prop_map(
                |(n, c, terms)| {
                    let mut f = Polynomial::new(n);
                    f.add_constant(f64::from(c));
                    for (lits, a) in terms {
                        let lits: Vec<Literal> =
                            lits.into_iter().map(|(v, s)| Literal::new(v, s)).collect();
                        f.add_term(f64::from(a), &lits);
                    }
                    f
                },
            )
        })
    }

    /// Terms as (literals, coefficient bits) in order, and the constant's bits.
    fn exact(f: &Polynomial) -> (Vec<(Vec<Literal>, u64)>, u64, usize) {
        (
            f.terms().map(|(l, a)| (l.to_vec(), a.to_bits())).collect(),
            f.constant().to_bits(),
            f.num_vars(),
        )
    }

    #[test]
    fn radix_sort_is_stable_and_sorted() {
        let mut items = Vec::new();
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for i in 0..5000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // Few distinct keys spread over all bytes, so runs of equal keys are long.
            items.push(((x % 37).wrapping_mul(0x0101_0101_0101_0101), i));
        }
        let mut expected = items.clone();
        expected.sort_by_key(|&(k, _)| k); // stable
        assert_eq!(radix_sort_by_key(items), expected);
        assert!(radix_sort_by_key(Vec::new()).is_empty());
    }

    proptest! {
        #[test]
        fn batch_equals_term_by_term(
            start in proptest::collection::vec((proptest::collection::vec((0u32..6, any::<bool>()), 0..=3), -3i32..=3), 0..3),
            terms in proptest::collection::vec((proptest::collection::vec((0u32..6, any::<bool>()), 0..=6), -10i32..=10), 0..40),
            later in proptest::collection::vec((0u32..6, any::<bool>()), 0..=3),
        ) {
            let lits = |v: &[(u32, bool)]| v.iter().map(|&(v, s)| Literal::new(v, s)).collect::<Vec<_>>();
            // Non-integral coefficients, so the order of the additions shows in the bits.
            let coeff = |a: i32| f64::from(a) / 3.0;
            let mut one = Polynomial::new(2);
            let mut batched = Polynomial::new(2);
            for (l, a) in &start {
                one.add_term(coeff(*a), &lits(l));
                batched.add_term(coeff(*a), &lits(l));
            }
            let mut batch = TermBatch::with_capacity(terms.len());
            for (l, a) in &terms {
                one.add_term(coeff(*a), &lits(l));
                batch.push(coeff(*a), &lits(l));
            }
            batched.add_batch(batch);
            prop_assert_eq!(exact(&one), exact(&batched));
            for (l, _) in &terms {
                prop_assert_eq!(one.coefficient(&lits(l)).to_bits(), batched.coefficient(&lits(l)).to_bits());
            }
            // A single term after a batch finds the batch's monomials.
            one.add_term(1.5, &lits(&later));
            batched.add_term(1.5, &lits(&later));
            prop_assert_eq!(exact(&one), exact(&batched));
        }
    }

    proptest! {
        #[test]
        fn multinomial_equals_original(f in arb_polynomial(7, 4)) {
            let m = f.to_multinomial().unwrap();
            prop_assert!(m.terms().all(|(l, _)| l.iter().all(|x| !x.is_negated())));
            let partial = f.to_multinomial_partial(1);
            for x in all_assignments(f.num_vars()) {
                prop_assert!((f.evaluate(&x) - partial.evaluate(&x)).abs() < 1e-9);
            }
            for x in all_assignments(f.num_vars()) {
                prop_assert!((f.evaluate(&x) - m.evaluate(&x)).abs() < 1e-9);
            }
        }

        #[test]
        fn posiform_equals_original_and_bounds_minimum(f in arb_polynomial(7, 4)) {
            let p = f.to_posiform();
            prop_assert!(p.terms().all(|(_, a)| a > 0.0));
            let (min, _) = f.brute_force_minimum();
            prop_assert!(p.constant() <= min + 1e-9);
            for x in all_assignments(f.num_vars()) {
                prop_assert!((f.evaluate(&x) - p.evaluate(&x)).abs() < 1e-9);
            }
        }

        #[test]
        fn fix_agrees_with_evaluation(f in arb_polynomial(7, 4), mask in 0u32..128, vals in 0u32..128) {
            let n = f.num_vars();
            let fixed: Vec<Option<bool>> = (0..n)
                .map(|i| (mask >> i & 1 == 1).then_some(vals >> i & 1 == 1))
                .collect();
            let g = f.fix(&fixed);
            for x in all_assignments(n) {
                let y: Vec<bool> = x.iter().zip(&fixed).map(|(&xi, fi)| fi.unwrap_or(xi)).collect();
                prop_assert!((f.evaluate(&y) - g.evaluate(&x)).abs() < 1e-9);
            }
        }
    }
}
