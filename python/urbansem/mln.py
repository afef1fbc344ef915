"""Markov logic networks: MAP and marginal inference and weight learning from
Alchemy/Tuffy-style files.

    >>> from urbansem import mln
    >>> values = mln.infer("prog.mln", ["evidence.db"], ["Smokes", "Cancer"])
    >>> values["Smokes(Anna)"]
    1
    >>> mln.marginals("prog.mln", ["evidence.db"], ["Cancer"])["Cancer(Anna)"]
    0.6224593312017901
    >>> text = mln.learn("prog.mln", ["training.db"], ["Smokes"], output="learnt.mln")
"""

from __future__ import annotations

import os
from typing import Any, Dict, Optional, Sequence, Tuple, Union

from ._urbansem import mln_infer as _infer
from ._urbansem import mln_learn as _learn
from ._urbansem import mln_marginals as _marginals

__all__ = ["infer", "infer_report", "learn", "learn_report", "marginals", "marginals_report"]

PathLike = Union[str, os.PathLike]


def infer_report(
    program: PathLike,
    evidence: Sequence[PathLike] = (),
    queries: Optional[Union[str, Sequence[str]]] = None,
    *,
    query_file: Optional[PathLike] = None,
    method: str = "qpbo",
    quadratize: str = "asm",
    representation: str = "auto",
    probe: bool = False,
    improve: int = 0,
    tabu: int = 20_000,
    polish: int = 0,
    flips: int = 1_000_000,
    chains: int = 2,
    seed: int = 0,
) -> Tuple[Dict[str, int], Dict[str, Any]]:
    """MAP inference: ``(values, report)``.

    ``values`` maps every ground atom of the query predicates (written as in evidence files,
    e.g. ``"Smokes(Anna)"``) to 0 or 1; ``report`` is the dict ``urbansem mln infer --json``
    prints (cost, lower bound, ground size, seconds). The options are the CLI's:
    ``method`` is ``qpbo``, ``maxwalksat`` or ``maxwalksat-monomials``.
    """
    if isinstance(queries, str):
        queries = [q.strip() for q in queries.split(",") if q.strip()]
    return _infer(
        os.fspath(program),
        [os.fspath(e) for e in evidence],
        list(queries) if queries is not None else None,
        query_file=os.fspath(query_file) if query_file is not None else None,
        method=method,
        quadratize=quadratize,
        representation=representation,
        probe=probe,
        improve=improve,
        tabu=tabu,
        polish=polish,
        flips=flips,
        chains=chains,
        seed=seed,
    )


def infer(
    program: PathLike,
    evidence: Sequence[PathLike] = (),
    queries: Optional[Union[str, Sequence[str]]] = None,
    **options: Any,
) -> Dict[str, int]:
    """MAP inference: each query atom → 0 or 1 (see :func:`infer_report` for the options)."""
    return infer_report(program, evidence, queries, **options)[0]


def marginals_report(
    program: PathLike,
    evidence: Sequence[PathLike] = (),
    queries: Optional[Union[str, Sequence[str]]] = None,
    *,
    query_file: Optional[PathLike] = None,
    samples: int = 5000,
    burn_in: int = 500,
    chains: int = 2,
    seed: int = 0,
) -> Tuple[Dict[str, float], Dict[str, Any]]:
    """Marginal inference (MC-SAT): ``(probabilities, report)``.

    ``probabilities`` maps every unknown atom of the query predicates to P(true);
    ``report`` is the dict ``urbansem mln infer --marginal --json`` prints (chain spread,
    atoms fixed by hard formulas, seconds). The options are the CLI's.
    """
    if isinstance(queries, str):
        queries = [q.strip() for q in queries.split(",") if q.strip()]
    return _marginals(
        os.fspath(program),
        [os.fspath(e) for e in evidence],
        list(queries) if queries is not None else None,
        query_file=os.fspath(query_file) if query_file is not None else None,
        samples=samples,
        burn_in=burn_in,
        chains=chains,
        seed=seed,
    )


def marginals(
    program: PathLike,
    evidence: Sequence[PathLike] = (),
    queries: Optional[Union[str, Sequence[str]]] = None,
    **options: Any,
) -> Dict[str, float]:
    """Marginal inference: each unknown query atom → P(true) (options: :func:`marginals_report`)."""
    return marginals_report(program, evidence, queries, **options)[0]


def learn_report(
    program: PathLike,
    training: Sequence[PathLike] = (),
    queries: Optional[Union[str, Sequence[str]]] = None,
    *,
    query_file: Optional[PathLike] = None,
    output: Optional[PathLike] = None,
    method: str = "perceptron",
    expectations: str = "map",
    samples: int = 500,
    epochs: int = 30,
    rate: float = 1.0,
    l2: float = 0.0,
    warm_start: bool = False,
    seed: int = 0,
) -> Tuple[str, Dict[str, Any]]:
    """Discriminative weight learning: ``(text, report)``.

    ``training`` holds the evidence and the labels (every atom of a query predicate listed
    in it is a label; unlisted ones are false). ``text`` is the program with the learnt
    weights (written to ``output`` too when given); ``report`` is the dict ``urbansem mln
    learn --json`` prints (learning curve, training errors, weights). ``method`` is
    ``perceptron`` or ``newton`` (diagonal Newton on MC-SAT samples), ``expectations`` ``map``
    or ``mcsat``; the other options are the CLI's.
    """
    if isinstance(queries, str):
        queries = [q.strip() for q in queries.split(",") if q.strip()]
    return _learn(
        os.fspath(program),
        [os.fspath(t) for t in training],
        list(queries) if queries is not None else None,
        query_file=os.fspath(query_file) if query_file is not None else None,
        output=os.fspath(output) if output is not None else None,
        method=method,
        expectations=expectations,
        samples=samples,
        epochs=epochs,
        rate=rate,
        l2=l2,
        warm_start=warm_start,
        seed=seed,
    )


def learn(
    program: PathLike,
    training: Sequence[PathLike] = (),
    queries: Optional[Union[str, Sequence[str]]] = None,
    **options: Any,
) -> str:
    """Weight learning: the program with the learnt weights (options: :func:`learn_report`)."""
    return learn_report(program, training, queries, **options)[0]
