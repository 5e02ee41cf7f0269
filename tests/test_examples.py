"""The tutorial docs/irl.md and its script examples/irl_tutorial.py say the same thing, and
what the page says the script prints and finds is what it prints and finds."""

from __future__ import annotations

import importlib.util
import re
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "irl.md"
SCRIPT = ROOT / "examples" / "irl_tutorial.py"
_NUMBER = re.compile(r"-?\d+(?:\.(\d+))?")


@pytest.fixture(scope="module")
def tutorial() -> types.ModuleType:
    spec = importlib.util.spec_from_file_location("irl_tutorial", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses and pickling look their module up
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def _blocks(kind: str) -> list[str]:
    return re.findall(rf"^```{kind}\n(.*?)^```", PAGE.read_text(), flags=re.S | re.M)


def _output(tutorial, capsys, *argv: str) -> str:
    capsys.readouterr()
    assert tutorial.main(list(argv)) == 0
    return capsys.readouterr().out


def same_but_rounding(printed: str, quoted: str) -> str | None:
    """What differs between two outputs beyond the last printed digit of a number, or None."""
    a, b = printed.strip().splitlines(), quoted.strip().splitlines()
    if len(a) != len(b):
        return f"{len(a)} lines printed, {len(b)} quoted"
    for x, y in zip(a, b, strict=True):
        if _NUMBER.sub("#", x) != _NUMBER.sub("#", y):
            return f"printed {x!r}, quoted {y!r}"
        for m, n in zip(_NUMBER.finditer(x), _NUMBER.finditer(y), strict=True):
            step = 10.0 ** -len(n.group(1) or "")
            if abs(float(m.group()) - float(n.group())) > 1.5 * step:
                return f"printed {m.group()}, quoted {n.group()} in {y!r}"
    return None


def test_the_comparison_of_outputs_catches_what_it_should():
    assert same_but_rounding("a 0.91 b 7.5%", "a 0.92 b 7.5%") is None
    assert "quoted 0.95" in same_but_rounding("a 0.91 b", "a 0.95 b")
    assert "quoted" in same_but_rounding("a 0.91 b", "a 0.91 c")
    assert "lines" in same_but_rounding("a\nb", "a")


def test_every_code_block_of_the_page_is_the_scripts():
    script = SCRIPT.read_text()
    blocks = _blocks("python")
    assert len(blocks) >= 6
    for block in blocks:
        assert block in script, f"docs/irl.md shows code the script does not have:\n{block}"


def test_the_page_quotes_what_the_script_prints(tutorial, capsys):
    quoted = next(b for b in _blocks("text") if b.startswith("30 runs"))
    problem = same_but_rounding(_output(tutorial, capsys), quoted)
    assert problem is None, problem


def test_mmap_birl_recovers_the_policy_where_the_face_value_baseline_does_not(tutorial):
    """The page's seed 1: MMAP-BIRL finds the person's policy, MAP-BIRL goes around an open
    door because it learns that the doorway costs; on seed 0 both find it."""
    mdp, sensor = tutorial.build_mdp(), tutorial.observation_model()
    found = {}
    for seed in (0, 1):
        demos = [tutorial.to_demonstration(run) for run in tutorial.simulate_log(mdp, seed=seed)]
        fitted = tutorial.fit_both(mdp, sensor, demos)
        found[seed] = tutorial.recovered(mdp, fitted)
    assert found[1] == {"MMAP-BIRL": True, "MAP-BIRL": False}
    assert found[0] == {"MMAP-BIRL": True, "MAP-BIRL": True}
    doorway = tutorial.FEATURES.index("in doorway")
    assert abs(fitted["MMAP-BIRL"].theta_[doorway]) < 0.1  # seed 1's fits
    assert fitted["MAP-BIRL"].theta_[doorway] < -0.15
    open_door = tutorial.STATES.index("door, door open")
    assert tutorial.ACTIONS[fitted["MAP-BIRL"].policy_[open_door]] == "around"


def test_the_counts_over_40_logs_are_the_pages(tutorial, capsys):
    quoted = next(b for b in _blocks("text") if "of 40 logs" in b)
    assert _output(tutorial, capsys, "--seeds", "40") == quoted


@pytest.mark.slow
def test_the_counts_with_another_beta_are_the_pages(tutorial, capsys):
    counts = {"1": (38, 8), "2.5": (39, 10), "10": (40, 10), "20": (38, 9)}
    sentence = ("with `--beta 1`, `2.5`, `10` and `20`, MMAP-BIRL finds the policy on "
                + ", ".join(str(m) for m, _ in list(counts.values())[:-1])
                + f" and {counts['20'][0]} of the 40 logs, MAP-BIRL on "
                + ", ".join(str(f) for _, f in list(counts.values())[:-1])
                + f" and {counts['20'][1]}.")
    assert sentence in " ".join(PAGE.read_text().split())
    for beta, (mmap, face) in counts.items():
        out = _output(tutorial, capsys, "--seeds", "40", "--beta", beta)
        assert out == (f"MMAP-BIRL: the person's policy on {mmap} of 40 logs\n"
                       f"MAP-BIRL: the person's policy on {face} of 40 logs\n"), beta


@pytest.mark.slow
def test_the_mcmc_posterior_reads_as_the_page_says(tutorial, capsys):
    text = " ".join(PAGE.read_text().split())
    assert "means within 0.03 of these, and 1.00 and 0.42" in text
    laplace = _output(tutorial, capsys).strip().splitlines()[-2:]
    mcmc = _output(tutorial, capsys, "--posterior", "mcmc").strip().splitlines()[-2:]
    for a, b in zip(laplace, mcmc, strict=True):
        means = [[float(x) for x in re.search(r"theta \[(.*?)\]", line).group(1).split()]
                 for line in (a, b)]
        assert max(abs(x - y) for x, y in zip(*means, strict=True)) <= 0.03 + 1e-9
    assert [line.rsplit(" ", 1)[1] for line in mcmc] == ["1.00", "0.42"]
