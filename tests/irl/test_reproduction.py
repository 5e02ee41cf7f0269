"""The paper's comparisons at its settings (slow: run with ``python -m pytest -m slow``)."""

import pytest

from irl.experiments import SweepConfig, run_sweep, summarize


@pytest.mark.slow
def test_forestworld_mmap_birl_beats_hidden_data_em_at_every_occlusion():
    """Fig. 1b at 30% noise: 10 batches of 10 demonstrations per occlusion level."""
    config = SweepConfig(
        domain="forestworld",
        points=((0.1, 0.3), (0.2, 0.3), (0.3, 0.3), (0.4, 0.3)),
        methods=("mmap-birl", "hidden-data-em"),
        batches=10, trajectories=10, length=15, seed=0,
    )
    rows = summarize(run_sweep(config, workers=2))
    ile = {(r["method"], r["occlusion"]): r["ile_mean"] for r in rows}
    for occ in (0.1, 0.2, 0.3, 0.4):
        assert ile["mmap-birl", occ] < ile["hidden-data-em", occ], occ


@pytest.mark.slow
def test_sorting_mmap_birl_recovers_the_expert_policy_under_occlusion_and_noise():
    """Fig. 3a: 12 demonstrations, 30% noise; MMAP-BIRL's policy is the expert's."""
    config = SweepConfig(
        domain="sorting", points=((0.2, 0.3), (0.4, 0.3)), methods=("mmap-birl",),
        batches=5, trajectories=12, length=20, seed=0,
    )
    rows = summarize(run_sweep(config, workers=2))
    for r in rows:
        assert r["normalized_ile_mean"] < 1.0, r
