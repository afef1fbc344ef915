"""Pseudo-Boolean optimization: minimise ``c + Σ a·Π literals`` over Boolean variables by
QSSR (quadratize, QPBO, fix the persistent variables, repeat; then improve).

A literal is a variable index ``i >= 0`` for xᵢ or ``~i`` (Python's bitwise not, ``-i - 1``)
for its complement 1 − xᵢ::

    >>> from urbansem import pbo
    >>> s = pbo.solve([(3, [0, 1]), (-2, [~2]), (-4, [0, 1, 2]), (1, [1])])
    >>> s.energy, s.lower_bound
    (-2.0, -2.0)
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ._urbansem import pbo_solve as _solve
from ._urbansem import pbo_solve_file as _solve_file

__all__ = ["Solution", "solve", "solve_file"]

Term = Tuple[float, Sequence[int]]


@dataclass(frozen=True)
class Solution:
    """A minimiser found by QSSR, with its certificate."""

    #: Value of the objective at ``assignment``.
    energy: float
    #: Roof-dual lower bound on the minimum (``energy == lower_bound`` proves optimality).
    lower_bound: float
    #: Share of the occurring variables whose value is persistent (part of some minimiser).
    labelled_fraction: float
    #: Whether ``assignment`` is proven to be a global minimiser.
    exact: bool
    #: 0/1 per variable (uint8).
    assignment: np.ndarray
    #: -1 (unknown), 0 or 1 per variable (int8): the persistent values.
    persistent: np.ndarray
    #: One dict per QSSR round.
    rounds: List[Dict[str, Any]]
    #: Seconds per phase (quadratize, solve, improve).
    seconds: Dict[str, float]


def solve(
    terms: Sequence[Term],
    *,
    constant: float = 0.0,
    num_vars: Optional[int] = None,
    quadratize: str = "ish",
    probe: bool = False,
    improve: int = 0,
    seed: int = 0,
) -> Solution:
    """Minimises ``constant + Σ coefficient · Π literal`` over the terms.

    ``quadratize`` is the order reduction for terms of degree ≥ 3 (``ish``, ``asm``, ``fix``);
    ``probe`` runs QPBO-P; ``improve`` QPBO-I rounds (seeded by ``seed``) label the rest.
    """
    d = _solve(
        [(float(c), [int(v) for v in lits]) for c, lits in terms],
        constant=constant,
        num_vars=num_vars,
        quadratize=quadratize,
        probe=probe,
        improve=improve,
        seed=seed,
    )
    return Solution(**d)


def solve_file(
    path: Union[str, os.PathLike],
    *,
    quadratize: str = "ish",
    probe: bool = False,
    improve: int = 0,
    seed: int = 0,
) -> Dict[str, Any]:
    """Reads an ``.opb`` objective and minimises it: the dict ``urbansem pbo solve --json``
    prints (``energy``, ``lower_bound``, ``assignment`` by variable name, …)."""
    return _solve_file(os.fspath(path), quadratize=quadratize, probe=probe, improve=improve, seed=seed)
