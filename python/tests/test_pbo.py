"""pbo.solve against brute force on small random polynomials, and pbo.solve_file against the
CLI on the same .opb file."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from urbansem import PboError, pbo


def energy(terms, constant: float, x) -> float:
    total = constant
    for c, lits in terms:
        v = 1
        for lit in lits:
            v &= x[~lit] ^ 1 if lit < 0 else x[lit]
        total += c * v
    return total


def random_terms(rng: np.random.Generator, n: int, m: int, degree: int):
    terms = []
    for _ in range(m):
        k = int(rng.integers(1, degree + 1))
        vs = rng.choice(n, size=k, replace=False)
        lits = [int(v) if rng.random() < 0.5 else ~int(v) for v in vs]
        terms.append((float(rng.integers(-9, 10)), lits))
    return terms


@pytest.mark.parametrize("quadratize", ["ish", "asm", "fix"])
@pytest.mark.parametrize("seed", range(8))
def test_matches_brute_force(quadratize: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 9
    terms = random_terms(rng, n, 14, 4)
    constant = float(rng.integers(-5, 5))
    best = min(energy(terms, constant, x) for x in itertools.product((0, 1), repeat=n))
    s = pbo.solve(terms, constant=constant, quadratize=quadratize, improve=3, seed=seed)
    assert s.assignment.shape == (n,) and s.assignment.dtype == np.uint8
    assert s.energy == pytest.approx(energy(terms, constant, s.assignment.tolist()))
    assert s.lower_bound <= best + 1e-9 <= s.energy + 1e-9
    if s.exact:
        assert s.energy == pytest.approx(best)
    # Persistent values agree with some minimiser: fixing them keeps the optimum.
    fixed = {i: int(v) for i, v in enumerate(s.persistent) if v >= 0}
    best_fixed = min(
        energy(terms, constant, x)
        for x in itertools.product((0, 1), repeat=n)
        if all(x[i] == v for i, v in fixed.items())
    )
    assert best_fixed == pytest.approx(best)


def test_submodular_quadratic_is_solved_exactly() -> None:
    # A chain with attractive pairs and unary pulls: QPBO labels everything.
    n = 40
    rng = np.random.default_rng(3)
    terms = [(float(rng.normal()), [i]) for i in range(n)]
    terms += [(-1.0, [i, i + 1]) for i in range(n - 1)]  # x_i x_{i+1}, coefficient < 0
    terms += [(-1.0, [~i, ~(i + 1)]) for i in range(n - 1)]
    s = pbo.solve(terms)
    assert s.labelled_fraction == 1.0
    assert s.energy == pytest.approx(s.lower_bound)


def test_solve_file_equals_the_cli(tmp_path: Path, cli) -> None:
    f = tmp_path / "f.opb"
    f.write_text("* #variable= 3 #constraint= 0\nmin: +3 x1 x2 -2 ~x3 -4 x1 x2 x3 +1 x2 ;\n")
    args = ("--quadratize", "asm", "--probe", "--improve", "5")
    ours = pbo.solve_file(f, quadratize="asm", probe=True, improve=5)
    theirs = cli("pbo", "solve", f, *args, "--json", json_out=True)
    for key in ("energy", "lower_bound", "objective", "assignment", "variables", "terms"):
        assert ours[key] == theirs[key], key
    untimed = lambda rounds: [{k: v for k, v in r.items() if not k.startswith("seconds")} for r in rounds]
    assert untimed(ours["rounds"]) == untimed(theirs["rounds"])


def test_bad_terms_are_errors(tmp_path: Path) -> None:
    with pytest.raises(PboError, match="not finite"):
        pbo.solve([(float("nan"), [0])])
    with pytest.raises(PboError, match="largest index"):
        pbo.solve([(1.0, [2**40])])
    with pytest.raises(PboError, match="num_vars"):
        pbo.solve([(1.0, [5])], num_vars=3)
    with pytest.raises(ValueError, match="quadratization"):
        pbo.solve([(1.0, [0])], quadratize="xyz")
    bad = tmp_path / "bad.opb"
    bad.write_text("* #variable= 42949672964 #constraint= 0\nmin: 1.5.3 x1 ;\n")
    with pytest.raises(PboError, match=r"bad.opb:2:6: coefficient"):
        pbo.solve_file(bad)
