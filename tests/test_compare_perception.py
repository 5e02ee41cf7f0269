"""``onionsort compare-perception``: two sets of models' figures side by side, with a tolerance
the sets resolve (two binomial standard errors at each figure's size, at least 0.02); and
scripts/compare_perception.py, the name the notes ran it by."""

import importlib.util
import json
import math
from pathlib import Path

import pytest

from onionsort.cli import main as cli
from onionsort.stages.compare_perception import compare_figures, mean_tolerance, tolerance

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "compare_perception.py"


def _rows(base, candidate):
    return compare_figures(base, candidate)[0]


def result(onion=0.9, ece=0.05, accuracy=0.9, camera=0.8):
    fused = {"onions": 40, "accuracy": accuracy, "precision": 1.0, "recall": 0.8, "ece": ece,
             "ece_by_chance": ece, "ece_by_chance_90": ece}
    level = {"views": 200, "found": 1.0, "rot_accuracy": 0.9, "view_accuracy": 0.8,
             "fused": {"noisy-or": fused}}
    return {"map_by_view": {"camera": {"map50": camera}, "all": {"map50": camera}},
            "accuracy": {"onion": onion}, "prediction_after_first_inspection": 0.95,
            "occlusion_recall": 1.0, "occlusion_precision": 1.0, "n_steps": 400,
            "session_swaps": {"sessions": 20, "swapped": 0},
            "inspection_classifier": {"levels": {"hard": {"robot": level}}}}


def test_a_loss_beyond_two_standard_errors_is_worse_and_one_within_is_not():
    rows = {r["figure"]: r for r in _rows(
        [result()], [result(onion=0.85, ece=0.06, accuracy=0.88, camera=0.83)])}
    onion = rows["state: onion"]  # 2 SE of 0.9 of 400 = 0.03 < 0.05 lost
    q = (0.9 * 400 + 2) / 404
    assert onion["tolerance"] == pytest.approx(2 * math.sqrt(q * (1 - q) / 400))
    assert onion["tolerance"] == pytest.approx(0.03, abs=0.001) and onion["verdict"] == "worse"
    fused = rows["inspection hard robot: fused by noisy-or, accuracy"]  # 40 onions
    assert fused["n"] == 40 and fused["verdict"] == "within"
    ece = rows["inspection hard robot: fused by noisy-or, ECE"]  # lower is better
    assert ece["gain"] == pytest.approx(-0.01) and ece["verdict"] == "within"
    assert rows["detector mAP@0.5, camera"]["verdict"] == "within"
    assert not any("by chance" in name for name in rows)  # a reference, not a figure


def test_figures_are_averaged_over_the_datasets_and_sized_by_their_sum():
    rows = {r["figure"]: r for r in _rows(
        [result(onion=0.9), result(onion=0.8)], [result(onion=0.9), result(onion=0.9)])}
    onion = rows["state: onion"]
    assert onion["base"] == pytest.approx(0.85) and onion["candidate"] == pytest.approx(0.9)
    assert onion["n"] == 800 and onion["verdict"] == "better"


def _write(tmp_path, name, r) -> str:
    path = tmp_path / name
    path.write_text(json.dumps(r))
    return str(path)


def test_the_command_prints_the_rows_and_the_figures_worse(tmp_path, capsys):
    base, cand = _write(tmp_path, "a.json", result()), _write(tmp_path, "b.json",
                                                              result(onion=0.8))
    assert cli(["compare-perception", "--base", base, "--candidate", cand]) == 0
    out = capsys.readouterr().out
    assert "worse beyond the tolerance: 1 of" in out and "state: onion" in out
    assert cli(["compare-perception", "--base", base, "--candidate", cand, "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["worse"] == ["state: onion"] and r["datasets"] == 1
    assert [x["figure"] for x in r["unchanged"] if x["verdict"] == "worse"] == ["state: onion"]


def test_results_of_two_datasets_are_refused_with_one_line(tmp_path, capsys):
    """A paired comparison needs both models' readings of one dataset."""
    other = result()
    other["n_steps"] = 500
    base, cand = _write(tmp_path, "a.json", result()), _write(tmp_path, "b.json", other)
    assert cli(["compare-perception", "--base", base, "--candidate", cand]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "not readings of one dataset" in err and "hold 500 and 400 steps" in err
    fewer = result()
    fewer["inspection_classifier"]["levels"]["hard"]["robot"]["views"] = 160  # --views 4
    cand = _write(tmp_path, "c.json", fewer)
    assert cli(["compare-perception", "--base", base, "--candidate", cand]) == 2
    assert "other inspection views per level" in capsys.readouterr().err
    found = result()  # the candidate found one onion fewer: the same views, compared
    found["inspection_classifier"]["levels"]["hard"]["robot"]["fused"]["noisy-or"]["onions"] = 39
    assert cli(["compare-perception", "--base", base, "--candidate",
                _write(tmp_path, "d.json", found)]) == 0


def shifted(r, seeds, drop=0.05):
    """``r`` as if read through the cameras of ``seeds`` too, each figure ``drop`` lower."""
    from onionsort.stages.calibrate import shift_summary

    lower = json.loads(json.dumps(r))
    lower["map_by_view"]["camera"]["map50"] -= drop
    return {**r, "camera_shift": {"seeds": seeds,
                                  "figures": shift_summary(r, [lower] * len(seeds))}}


def test_through_other_cameras_it_gives_each_models_drop_and_refuses_other_seeds(tmp_path,
                                                                                  capsys):
    base = _write(tmp_path, "a.json", shifted(result(), [11, 12], drop=0.06))
    cand = _write(tmp_path, "b.json", shifted(result(), [11, 12], drop=0.03))
    assert cli(["compare-perception", "--base", base, "--candidate", cand, "--json"]) == 0
    rows = {x["figure"]: x for x in json.loads(capsys.readouterr().out)["camera_shift"]}
    camera = rows["detector mAP@0.5, camera"]
    assert camera["base_drop"] == pytest.approx(0.06)
    assert camera["candidate_drop"] == pytest.approx(0.03)
    assert camera["candidate_mean"] == pytest.approx(0.77)
    other = _write(tmp_path, "c.json", shifted(result(), [11, 13]))
    assert cli(["compare-perception", "--base", base, "--candidate", other]) == 2
    assert "different seeds ([11, 13] against [11, 12])" in capsys.readouterr().err


def test_the_notes_script_runs_the_same_comparison_and_writes_its_rows(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("compare_perception_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    base, cand = _write(tmp_path, "a.json", result()), _write(tmp_path, "b.json",
                                                              result(onion=0.8))
    assert script.main(["--base", base, "--candidate", cand,
                        "--json", str(tmp_path / "rows.json")]) == 0
    assert "worse beyond the tolerance: 1 of" in capsys.readouterr().out
    rows = json.loads((tmp_path / "rows.json").read_text())["unchanged"]
    assert [r["figure"] for r in rows if r["verdict"] == "worse"] == ["state: onion"]
    assert script.main(["--base", base, "--base", base, "--candidate", cand]) == 2
    assert "one --candidate result per --base one" in capsys.readouterr().err


def fused_result(precision, recall=1.0, blemished=20, called=None, counts=True):
    r = result()
    f = r["inspection_classifier"]["levels"]["hard"]["robot"]["fused"]["noisy-or"]
    f.update(precision=precision, recall=recall)
    if counts:
        f.update(blemished=blemished, called_blemished=called)
    return r


def test_precision_and_recall_are_sized_by_what_they_count():
    """Precision counts the onions called blemished, recall the blemished ones; a result
    written before those counts is sized by its onions."""
    name = "inspection hard robot: fused by noisy-or, "
    rows = {r["figure"]: r for r in _rows(
        [fused_result(20 / 21, called=21)], [fused_result(1.0, called=20)])}
    assert rows[name + "precision"]["n"] == 21
    assert rows[name + "recall"]["n"] == 20 and rows[name + "accuracy"]["n"] == 40
    old = {r["figure"]: r for r in _rows(
        [fused_result(1.0, counts=False)], [fused_result(1.0, counts=False)])}
    assert old[name + "precision"]["n"] == old[name + "recall"]["n"] == 40
    mixed = {r["figure"]: r for r in _rows(  # an old baseline, a new candidate
        [fused_result(1.0, counts=False)], [fused_result(20 / 21, called=21)])}
    assert mixed[name + "precision"]["n"] == 21


def test_one_onion_off_a_perfect_figure_is_within_and_three_are_worse():
    """At a rate of 1.000 the plain standard error is 0, and the 0.02 floor is finer than one
    onion of 41: the tolerance is at Agresti and Coull's rate, which one count never exceeds."""
    name = "inspection hard robot: fused by noisy-or, precision"
    one = {r["figure"]: r for r in _rows(
        [fused_result(1.0, called=41)], [fused_result(40 / 41, called=41)])}[name]
    assert one["tolerance"] > 1 / 41 and one["verdict"] == "within"
    three = {r["figure"]: r for r in _rows(
        [fused_result(1.0, called=41)], [fused_result(38 / 41, called=41)])}[name]
    assert three["verdict"] == "worse"
    assert tolerance(0.5, 10_000) == 0.02  # the floor holds for large sets


def test_over_sets_of_unequal_sizes_the_tolerance_is_that_of_their_mean():
    """Over sets of one size, two standard errors at the summed size; a small set beside a
    large one weighs as much in the mean, so the tolerance is wider than at their sum."""
    assert mean_tolerance(0.8, [400, 400]) == pytest.approx(tolerance(0.8, 800))
    assert mean_tolerance(0.5, [100, 1000]) > 1.5 * tolerance(0.5, 1100)
    assert mean_tolerance(0.5, [0, 0]) == 0.02


def test_a_figure_some_result_lacks_is_listed_not_compared(tmp_path, capsys):
    paper = result()
    paper["inspection_classifier"]["levels"] = {
        "paper": paper["inspection_classifier"]["levels"].pop("hard")}
    paper["n_steps"] = 401
    argv = ["compare-perception", "--base", _write(tmp_path, "a.json", result()),
            "--base", _write(tmp_path, "b.json", paper),
            "--candidate", _write(tmp_path, "c.json", result()),
            "--candidate", _write(tmp_path, "d.json", paper)]
    assert cli(argv) == 0
    assert "not compared, lacking in some result: inspection hard robot: onion found" in \
        capsys.readouterr().out
    assert cli([*argv, "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert "inspection paper robot: fused by noisy-or, recall" in r["not_compared"]
    assert "state: onion" in [x["figure"] for x in r["unchanged"]]


def test_results_in_the_wrong_order_or_read_another_way_are_refused(tmp_path, capsys):
    def refused(base, cand, *words):
        assert cli(["compare-perception", "--base", _write(tmp_path, "a.json", base),
                    "--candidate", _write(tmp_path, "b.json", cand)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and all(w in err for w in words), err

    a, b = result(), result()
    a["data"] = {"name": "d9101", "seed": 9101, "frames": 1200, "difficulty": "clean"}
    b["data"] = {**a["data"], "name": "d9121", "seed": 9121}
    refused(a, b, "readings of different datasets", "'seed': 9121", "--base's order")
    bare = result()
    del bare["inspection_classifier"]
    refused(result(), bare, "b.json was read without the inspection", "a.json with it")
    refused(shifted(result(), [11]), result(), "a.json was read through other cameras",
            "b.json was not")
    one = shifted(result(), [11])
    one["camera_shift"]["one_camera"] = True
    refused(shifted(result(), [11]), one, "--one-camera")


def test_a_result_of_the_notes_older_form_is_read_as_one_through_the_cameras(tmp_path,
                                                                            capsys):
    """``{"unchanged": ..., "11": ..., "12": ...}``: the unchanged figures and each seed's."""
    lower = result(camera=0.75)
    old = {"unchanged": result(), "11": lower, "12": lower}
    base = _write(tmp_path, "a.json", old)
    cand = _write(tmp_path, "b.json", shifted(result(), [11, 12], drop=0.02))
    assert cli(["compare-perception", "--base", base, "--candidate", cand, "--json"]) == 0
    rows = {x["figure"]: x for x in json.loads(capsys.readouterr().out)["camera_shift"]}
    assert rows["detector mAP@0.5, camera"]["base_drop"] == pytest.approx(0.05)
    broken = _write(tmp_path, "c.json", {"unchanged": result(), "11": [1, 2]})
    assert cli(["compare-perception", "--base", broken, "--candidate", broken]) == 2
    assert "c.json is not an `eval-perception --json` result: its '11' is not an object" in \
        capsys.readouterr().err
