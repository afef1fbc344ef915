"""mln.infer, mln.marginals and mln.learn: the CLI's answer and report on the same files,
against exhaustive search on a small program, and clear errors."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from urbansem import MlnError, mln


@pytest.fixture(scope="module")
def smoke(data: Path) -> Path:
    return data / "mln" / "smoke" / "tuffy"


def test_infer_equals_the_cli(smoke: Path, tmp_path: Path, cli) -> None:
    values, report = mln.infer_report(
        smoke / "prog.mln", [smoke / "evidence.db"], query_file=smoke / "query.db", seed=3
    )
    result = tmp_path / "result.txt"
    theirs = cli(
        "mln", "infer", "-i", smoke / "prog.mln", "-e", smoke / "evidence.db",
        "--query-file", smoke / "query.db", "--seed", "3", "-r", result, "--json",
        json_out=True,
    )
    lines = [l.rsplit(" ", 1) for l in result.read_text().splitlines()]
    assert values == {atom: int(v) for atom, v in lines}
    for key in ("cost", "lower_bound", "ground_atoms", "ground_factors", "true_atoms", "method"):
        assert report[key] == theirs[key], key


def test_marginals_equal_the_cli(smoke: Path, tmp_path: Path, cli) -> None:
    probs, report = mln.marginals_report(
        smoke / "prog.mln", [smoke / "evidence.db"], query_file=smoke / "query.db",
        samples=1000, seed=2,
    )
    result = tmp_path / "marginals.txt"
    theirs = cli(
        "mln", "infer", "--marginal", "--samples", "1000", "-i", smoke / "prog.mln",
        "-e", smoke / "evidence.db", "--query-file", smoke / "query.db", "--seed", "2",
        "-r", result, "--json", json_out=True,
    )
    # Same seed, same chains: the same numbers, bit for bit.
    assert probs == theirs["marginals"]
    lines = [l.split("\t") for l in result.read_text().splitlines()]
    assert {atom: round(p, 4) for atom, p in probs.items()} == {a: float(p) for p, a in lines}
    for key in ("samples", "chains", "ground_atoms", "fixed_atoms", "max_chain_spread"):
        assert report[key] == theirs[key], key
    with pytest.raises(ValueError):
        mln.marginals(smoke / "prog.mln", [smoke / "evidence.db"], "Cancer", samples=0)


def test_map_state_is_optimal_on_a_small_program(tmp_path: Path) -> None:
    # Four people, two friendships: 4 Smokes + 4 Cancer unknown atoms → 256 worlds.
    prog = tmp_path / "prog.mln"
    prog.write_text(
        "Smokes(person)\nCancer(person)\nFriends(person, person)\n"
        "1.5 Smokes(x) => Cancer(x)\n"
        "1.1 Friends(x, y) ^ Smokes(x) => Smokes(y)\n"
        "-0.7 Smokes(x)\n"
        "0.4 Cancer(x)\n"
    )
    ev = tmp_path / "evidence.db"
    ev.write_text("Friends(A, B)\nFriends(B, C)\nSmokes(A)\n!Cancer(D)\n")
    values, report = mln.infer_report(prog, [ev], ["Smokes", "Cancer"])
    people = ["A", "B", "C", "D"]

    def cost(s: dict, c: dict) -> float:
        total = 0.0
        friends = {("A", "B"), ("B", "C")}
        for x in people:  # violated weight of positive formulas, satisfied weight of negative
            total += 1.5 * (s[x] and not c[x])
            total += 0.7 * s[x]
            total += 0.4 * (not c[x])
            for y in people:
                total += 1.1 * ((x, y) in friends and s[x] and not s[y])
        return total

    best = None
    unknown_s = ["B", "C", "D"]
    unknown_c = ["A", "B", "C"]
    for bits in itertools.product((False, True), repeat=6):
        s = {"A": True, **dict(zip(unknown_s, bits[:3]))}
        c = {"D": False, **dict(zip(unknown_c, bits[3:]))}
        v = cost(s, c)
        best = v if best is None else min(best, v)
    s = {p: bool(values.get(f"Smokes({p})", p == "A")) for p in people}
    c = {p: bool(values.get(f"Cancer({p})", False)) for p in people}
    assert cost(s, c) == pytest.approx(best)
    assert set(values) >= {f"Smokes({p})" for p in unknown_s} | {f"Cancer({p})" for p in unknown_c}


def test_errors_name_the_file(tmp_path: Path, smoke: Path) -> None:
    with pytest.raises(MlnError, match="missing.mln"):
        mln.infer(tmp_path / "missing.mln", [], ["Smokes"])
    bad = tmp_path / "bad.mln"
    bad.write_text("Smokes(person)\n1.0 Smokes(x) => \n")
    with pytest.raises(MlnError, match="bad.mln"):
        mln.infer(bad, [], ["Smokes"])
    with pytest.raises(MlnError, match="Unknown|unknown"):
        mln.infer(smoke / "prog.mln", [smoke / "evidence.db"], ["NoSuchPredicate"])
    with pytest.raises(ValueError, match="no query"):
        mln.infer(smoke / "prog.mln", [smoke / "evidence.db"])
    with pytest.raises(ValueError, match="method"):
        mln.infer(smoke / "prog.mln", [smoke / "evidence.db"], ["Smokes"], method="gibbs")


def test_learn_equals_the_cli(tmp_path: Path, cli) -> None:
    prog = tmp_path / "prog.mln"
    prog.write_text(
        "Smokes(person)\nCancer(person)\nFriends(person, person)\n"
        "0 Smokes(x) => Cancer(x)\n0 Friends(x, y) ^ Smokes(x) => Smokes(y)\n"
    )
    training = tmp_path / "training.db"
    training.write_text(
        "Friends(Anna, Bob)\nFriends(Bob, Chris)\nFriends(Chris, Dora)\nFriends(Edo, Fay)\n"
        "Smokes(Anna)\nSmokes(Bob)\nSmokes(Chris)\nSmokes(Dora)\n"
        "Cancer(Anna)\nCancer(Bob)\nCancer(Dora)\n"
    )
    for method, expectations in (("perceptron", "map"), ("newton", "mcsat")):
        ours = tmp_path / f"py-{method}.mln"
        text, report = mln.learn_report(
            prog, [training], "Smokes,Cancer", output=ours, method=method,
            expectations=expectations, samples=200, epochs=8, seed=5,
        )
        theirs_path = tmp_path / f"cli-{method}.mln"
        theirs = cli(
            "mln", "learn", "-i", prog, "-e", training, "-q", "Smokes,Cancer",
            "-o", theirs_path, "--method", method, "--expectations", expectations,
            "--samples", "200", "--epochs", "8", "--seed", "5", "--json", json_out=True,
        )
        # Same seed, same learning: the same program, byte for byte.
        assert ours.read_text() == text == theirs_path.read_text()
        for key in ("method", "errors_start", "errors_learnt", "weights", "labels", "ground_atoms"):
            assert report[key] == theirs[key], key
        assert report["errors_learnt"] <= report["errors_start"]
    assert mln.learn(prog, [training], ["Smokes", "Cancer"], epochs=2).startswith("Smokes(")
    with pytest.raises(ValueError):
        mln.learn(prog, [training], "Smokes", method="gradient-boosting")
    with pytest.raises(MlnError):
        mln.learn(tmp_path / "missing.mln", [training], "Smokes")
