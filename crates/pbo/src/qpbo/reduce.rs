//! Restriction of a quadratic function by fixing variables and identifying literals.
//!
//! Probing and improve solve many restricted copies of one function: every original
//! variable becomes either a constant or a literal (a variable of the restricted function,
//! possibly negated). Pairwise terms collapse to unary terms or constants as needed, so the
//! restricted function equals the original on every assignment consistent with the map.

use super::Qpbo;
use crate::maxflow::Capacity;

/// What an original variable becomes in the restricted function.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Subst {
    /// The variable is fixed to this value.
    Value(bool),
    /// xᵢ = y_k xor `negated`.
    Lit(u32, bool),
}

impl Subst {
    #[inline]
    fn value_in(self, y: &[bool]) -> bool {
        match self {
            Subst::Value(v) => v,
            Subst::Lit(k, neg) => y[k as usize] ^ neg,
        }
    }
}

impl<T: Capacity> Qpbo<T> {
    /// The function restricted by `subst` (one entry per original variable) over
    /// `num_new` variables.
    pub(crate) fn restrict(&self, subst: &[Subst], num_new: usize) -> Qpbo<T> {
        let mut r = Qpbo::new(num_new, self.pairs.len());
        r.scale = self.scale;
        let mut constant = self.constant;
        let mut unary = vec![[T::ZERO; 2]; num_new];
        for (u, &s) in self.unary.iter().zip(subst) {
            match s {
                Subst::Value(v) => constant += u[usize::from(v)],
                Subst::Lit(k, neg) => {
                    let ru = &mut unary[k as usize];
                    ru[0] += u[usize::from(neg)];
                    ru[1] += u[usize::from(!neg)];
                }
            }
        }
        for p in &self.pairs {
            match (subst[p.i as usize], subst[p.j as usize]) {
                (Subst::Value(vi), Subst::Value(vj)) => constant += p.eval(vi, vj),
                (Subst::Value(vi), Subst::Lit(k, nj)) => {
                    let ru = &mut unary[k as usize];
                    ru[0] += p.eval(vi, nj);
                    ru[1] += p.eval(vi, !nj);
                }
                (Subst::Lit(k, ni), Subst::Value(vj)) => {
                    let ru = &mut unary[k as usize];
                    ru[0] += p.eval(ni, vj);
                    ru[1] += p.eval(!ni, vj);
                }
                (Subst::Lit(k, ni), Subst::Lit(l, nj)) => {
                    if k == l {
                        let ru = &mut unary[k as usize];
                        ru[0] += p.eval(ni, nj);
                        ru[1] += p.eval(!ni, !nj);
                    } else {
                        r.add_pairwise(
                            k as usize,
                            l as usize,
                            p.eval(ni, nj),
                            p.eval(ni, !nj),
                            p.eval(!ni, nj),
                            p.eval(!ni, !nj),
                        );
                    }
                }
            }
        }
        r.add_constant(constant);
        for (k, u) in unary.into_iter().enumerate() {
            r.add_unary(k, u[0], u[1]);
        }
        r
    }
}

/// The original assignment given by `subst` and an assignment `y` of the restricted function.
pub(crate) fn expand(subst: &[Subst], y: &[bool]) -> Vec<bool> {
    subst.iter().map(|s| s.value_in(y)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restriction_agrees_with_original_on_consistent_assignments() {
        let mut q = Qpbo::<i32>::new(4, 4);
        q.add_constant(3);
        q.add_unary(0, 1, -2);
        q.add_unary(3, 5, 7);
        q.add_pairwise(0, 1, 1, 2, 3, 4);
        q.add_pairwise(1, 2, -4, 6, 0, 1);
        q.add_pairwise(2, 3, 2, -1, 9, 0);
        q.add_pairwise(0, 3, 0, 0, 5, -5);
        // x1 = 1, x3 = ¬x0, x2 = y1.
        let subst = [
            Subst::Lit(0, false),
            Subst::Value(true),
            Subst::Lit(1, false),
            Subst::Lit(0, true),
        ];
        let r = q.restrict(&subst, 2);
        for bits in 0..4u32 {
            let y = [bits & 1 == 1, bits & 2 == 2];
            let x = expand(&subst, &y);
            assert_eq!(r.energy(&y), q.energy(&x));
        }
    }
}
