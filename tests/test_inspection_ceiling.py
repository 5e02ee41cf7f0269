"""``bench/inspection_ceiling.py``: the sorter's views read from the renderer's truth (the
measurement itself: docs/perception.md)."""

import pytest

from bench.inspection_ceiling import TruthModels, truth_tables
from onionsort.cli import main as onionsort
from onionsort.stages.calibrate import measure_perception
from onionsort.stages.models import PerceptionModels


@pytest.fixture(scope="module")
def paper(tmp_path_factory):
    root = tmp_path_factory.mktemp("ceiling") / "paper"
    assert onionsort(["dataset", "--frames", "72", "--steps-per-session", "8",
                      "--robot-onions", "0", "--seed", "8", "--difficulty", "paper",
                      "--workers", "1", "--out", str(root)]) == 0
    return root


def test_the_truth_tables_read_rot_only_where_the_onion_is_blemished(paper):
    tables = truth_tables(paper, "all")
    rot, cls = tables["rot"], tables["class"]
    assert rot.keys() == cls.keys()
    shown = [k for k, v in cls.items() if v is not None]
    assert shown and {cls[k] for k in shown} <= {0.01, 0.99}
    assert {k for k, v in rot.items() if v is None} == {k for k, v in cls.items() if v is None}
    # rot is read only on a blemished onion; a blemished one may show none
    assert all(cls[k] == 0.99 for k in shown if rot[k] == 0.99)
    assert all(rot[k] == 0.01 for k in shown if cls[k] == 0.01)
    # a detector of any rot pixel reads a trace as rot, and agrees with the rot detector
    # everywhere else
    trace = tables["trace"]
    assert all(trace[k] == (0.99 if rot[k] == 0.5 else rot[k]) for k in shown)


def test_a_perfect_class_reader_reads_no_session_backwards(paper):
    models = PerceptionModels.load(None, "cpu")
    truth = TruthModels.reading(models, truth_tables(paper, "all")["class"])
    _, read = measure_perception(truth, paper, "all")
    assert read["session_swaps"]["swapped"] == 0
    assert sum(read["session_swaps"]["swapped_reads"]) == 0
    # a view the table does not hold is an error that says so, not a silent guess
    with pytest.raises(SystemExit, match="not among"):
        TruthModels.reading(models, {}).inspector().view_probabilities([paper_view(paper)])


def paper_view(root):
    from recordings.labels.dataset import read_split
    return next(iter(read_split(root, "test", view="inspection"))).color
