"""Stage ``report``: a run folder's settings and results as one Markdown page.

Reads the files a run folder already holds and writes ``RUN/report.md`` beside them; it never
recomputes a result. What the folder is comes from what it holds (:func:`run_kind`):

=============  ======================  =====================================================
kind           written by              recognised by
=============  ======================  =====================================================
demo           ``onionsort demo``      ``results.json`` with every method's pooled counts
experiment     ``onionsort             ``summary.json`` with the sweep's points
               experiment``
learn          ``onionsort learn``     ``model.json`` (a learned model)
evaluate       ``onionsort evaluate``  ``evaluation.json`` (a sort's counts)
=============  ======================  =====================================================

The page embeds figures by relative links: ``report_pr.png`` (precision and recall per method,
drawn here from the recorded counts and intervals, written atomically), and the run's own
``confusion.png``, ``learning_curve.png``, ``policy_confidence.png`` and sweep plots where they
exist; every image it links exists. It lists the run's Rerun (``.rrd``) and MCAP recordings
with the command that opens each. ``report.md`` is derived: running the stage again replaces
it (through a temporary name).

Example::

    from onionsort.stages.report import ReportConfig, report
    path = report(ReportConfig(run=Path("runs/demo-quick")))   # runs/demo-quick/report.md
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Sequence
from pathlib import Path

from onionsort.configs.report import ReportConfig
from onionsort.stages.base import check_output_folder, log_config, write_text
from onionsort.stages.table1 import METHODS, PAPER_TABLE_1, table

__all__ = ["KINDS", "PR_FIGURE", "REPORT_FILE", "ReportConfig", "report", "run_kind"]

logger = logging.getLogger(__name__)

REPORT_FILE = "report.md"
#: The precision/recall figure the report draws beside itself.
PR_FIGURE = "report_pr.png"
#: The kinds of run folder a report is written for, in the order they are recognised.
KINDS = ("demo", "experiment", "learn", "evaluate")
#: The sweep's figures (``onionsort.plots.plot_sweep``) in the order the report shows them,
#: with their captions; the data-efficiency curve first.
SWEEP_FIGURES = (
    ("normalized_ile_vs_demonstrations.png", "normalized ILE against the number of "
                                             "demonstrations (data efficiency)"),
    ("exact_policy_vs_demonstrations.png", "exact-policy rate against the number of "
                                           "demonstrations"),
    ("ile_vs_occlusion.png", "ILE against occlusion"),
    ("ile_vs_noise.png", "ILE against observation noise, without occlusion"),
    ("vs_learner_beta.png", "normalized ILE and exact-policy rate per learner setting"),
    ("seconds_vs_occlusion.png", "fit time against occlusion"),
    ("seconds_vs_demonstrations.png", "fit time against the number of demonstrations"),
)
CELLS = ("tp", "fp", "tn", "fn")
_EXPECTED = ("a run folder of `onionsort demo`, `onionsort experiment`, `onionsort learn` or "
             "`onionsort evaluate` (results.json, summary.json, model.json or evaluation.json)")


def report(config: ReportConfig) -> Path:
    """Write ``config.run/report.md`` for the run folder's kind; return its path."""
    log_config("report", config)
    folder = config.run
    kind = run_kind(folder)
    check_output_folder(folder, "RUN_DIR")
    lines = _WRITERS[kind](folder)
    while lines and not lines[-1]:
        lines.pop()
    lines += ["", *_recordings(folder)]
    path = write_text(folder / REPORT_FILE, "\n".join(lines).rstrip() + "\n")
    logger.info("report: wrote %s (a %s run)", path, kind)
    return path


def run_kind(folder: Path) -> str:
    """Which of :data:`KINDS` the run folder ``folder`` is, from the files it holds.

    Raises
    ------
    FileNotFoundError, NotADirectoryError
        If ``folder`` does not exist or is a file.
    ValueError
        If it is none of the kinds (with what was expected), an interrupted demo or sweep, or
        its file is not what its name says.
    """
    from onionsort.stages.learn import MODEL_FORMAT

    folder = Path(folder)
    if not folder.exists():
        raise FileNotFoundError(f"RUN_DIR {folder} does not exist; give {_EXPECTED}")
    if not folder.is_dir():
        raise NotADirectoryError(f"RUN_DIR {folder} is a file, not a folder; give {_EXPECTED}")
    if (folder / "results.json").is_file():
        if _has(_read(folder / "results.json"), "methods", "paper"):
            return "demo"
    elif (folder / "progress" / "config.json").is_file():
        raise ValueError(f"{folder} holds an unfinished demo (progress/ but no results.json); "
                         f"finish it with `onionsort demo --resume --out {folder}` and the "
                         "settings it was started with (progress/config.json) first")
    if (folder / "summary.json").is_file():
        if _has(_read(folder / "summary.json"), "points", "config"):
            return "experiment"
    elif (folder / "results.csv.partial").is_file():
        raise ValueError(f"{folder} holds an interrupted sweep (results.csv.partial but no "
                         "summary.json); finish it with `onionsort experiment ... --resume` "
                         "first")
    model, evaluation = folder / "model.json", folder / "evaluation.json"
    if model.is_file() and _read(model).get("format") == MODEL_FORMAT:
        return "learn"
    if evaluation.is_file() and _has(_read(evaluation), *CELLS):
        return "evaluate"
    runs = sorted(p for p in folder.iterdir() if p.is_dir() and any(
        (p / name).is_file() for name in ("model.json", "evaluation.json")))
    if runs:  # e.g. `onionsort learn --method A,B`: one run folder per method
        raise ValueError(f"{folder} is no run folder itself but holds run folders ("
                         + ", ".join(p.name for p in runs) + "); report each, e.g. "
                         f"`onionsort report {runs[0]}`")
    held = sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))
    what = ("it is empty" if not held else "it holds " + ", ".join(held[:5])
            + (", ..." if len(held) > 5 else ""))
    raise ValueError(f"{folder} is no run folder ({what}); give {_EXPECTED}")


# --- reading -----------------------------------------------------------------------------


def _read(path: Path) -> dict:
    """A run file's JSON object, or a one-line ``ValueError`` naming the file."""
    try:
        doc = json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not JSON ({exc}); the run folder is damaged") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path} holds a JSON {type(doc).__name__}, not the object onionsort "
                         "writes; the run folder is damaged")
    return doc


def _has(doc: dict, *keys: str) -> bool:
    return all(k in doc for k in keys)


def _demo_repeat(folder: Path) -> dict | None:
    """The demo's record of the learning run ``folder`` (a method folder of a demo, alone or
    in ``repeat_K``): its seed, counts and ILE; None outside a demo."""
    root, k = folder.parent, 0
    if root.name.startswith("repeat_") and root.name[7:].isdigit():
        root, k = root.parent, int(root.name[7:])
    try:
        runs = json.loads((root / "results.json").read_text())["methods"][folder.name]
        run = runs["per_repeat"][k]
    except (OSError, json.JSONDecodeError, KeyError, IndexError, TypeError):
        return None
    return run if isinstance(run, dict) else None


# --- formatting --------------------------------------------------------------------------


def _table(header: Sequence[str], rows: Iterable[Sequence]) -> list[str]:
    """A Markdown table."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(str(c) for c in row) + " |" for row in rows)]


def _rate(value, ci=None, ci_fmt: str = ".2f") -> str:
    """``value`` to 3 decimals, with its interval ``ci`` (low, high) where given."""
    if value is None:
        return "-"
    text = f"{value:.3f}"
    if ci is not None:
        text += f" [{ci[0]:{ci_fmt}}, {ci[1]:{ci_fmt}}]"
    return text


def _num(value, fmt: str = ".3f") -> str:
    return "-" if value is None else format(value, fmt)


def _image(folder: Path, rel: str, caption: str) -> list[str]:
    """A Markdown image of ``folder/rel``, or nothing when the file is not there."""
    return [f"![{caption}]({rel})", ""] if (folder / rel).is_file() else []


def _settings(rows: Iterable[tuple[str, object]]) -> list[str]:
    return ["## Settings", "", *_table(("setting", "value"),
                                       ((k, v) for k, v in rows if v is not None)), ""]


def _preamble(kind: str, folder: Path, sources: str) -> list[str]:
    return [f"# {kind} report: {folder.resolve().name}", "",
            f"Written by `onionsort report` from {sources} in this folder; it is derived from "
            "those files and is replaced when the report is written again.", ""]


def _pr_figure(folder: Path, rows: list[dict], title: str = "") -> list[str]:
    """Draw ``report_pr.png`` from ``rows`` (:func:`onionsort.plots.sorting_scores_figure`)
    and link it."""
    from onionsort.plots import sorting_scores_figure

    sorting_scores_figure(rows, folder / PR_FIGURE, title=title)
    return [f"![precision and recall per method]({PR_FIGURE})", ""]


def _recordings(folder: Path) -> list[str]:
    """The run's ``.rrd`` and ``.mcap`` files with the command that opens each."""
    files = sorted([*folder.rglob("*.rrd"), *folder.rglob("*.mcap")],
                   key=lambda p: p.relative_to(folder).as_posix())
    lines = ["## Recordings", ""]
    if not files:
        return [*lines, "This run holds no Rerun (`.rrd`) or MCAP (`.mcap`) recordings."]
    rows = []
    for path in files:
        rel = path.relative_to(folder).as_posix()
        what = "Rerun recording" if path.suffix == ".rrd" else "MCAP session"
        rows.append((f"`{rel}`", what, f"{path.stat().st_size / 1e6:.1f} MB", f"`rerun {rel}`"))
    lines += ["Paths are relative to this folder (open them from here).", "",
              *_table(("file", "kind", "size", "open with"), rows)]
    if any(path.suffix == ".mcap" for path in files):
        lines += ["", "An MCAP session also opens in Foxglove (its 3D, Image and Plot panels), "
                  "converts to a Rerun file with `rerun mcap convert FILE.mcap -o FILE.rrd`, "
                  "and reads with `recordings.open_session` (see docs/session-format.md)."]
    return lines


# --- demo --------------------------------------------------------------------------------


def _demo(folder: Path) -> list[str]:
    results = _read(folder / "results.json")
    started = {}
    if (folder / "progress" / "config.json").is_file():
        started = _read(folder / "progress" / "config.json")
    repeats = int(results.get("repeats", 1))
    seed = results.get("seed", 0)
    methods = [m for m in METHODS if m in results["methods"]] + \
        [m for m in results["methods"] if m not in METHODS]
    inspection = results.get("inspection", {})
    costs = ("the task's reward's" if started.get("miss_cost") is None
             and started.get("waste_cost") is None
             else f"miss {started.get('miss_cost')}, waste {started.get('waste_cost')}")
    lines = _preamble("Demo", folder, "`results.json`, `calibration/` and the method folders")
    lines += _settings([
        ("size", "quick" if results.get("quick") else "full"),
        ("seed", seed if repeats == 1 else f"{seed} .. {seed + repeats - 1} (one per repeat)"),
        ("repeats", repeats),
        ("sessions per repeat", results.get("sessions")),
        ("line-up", f"{results.get('onions')} onions, {results.get('blemished')} blemished"),
        ("difficulty", results.get("difficulty")),
        ("inspection", f"{inspection.get('views')} views at most, bins from "
                       f"P(blemished) >= {_num(inspection.get('threshold'), '.2f')}, fused by "
                       f"{inspection.get('fusion')}" if inspection else None),
        ("costs of a miss and of waste", costs if started else None),
        ("perception models", (started.get("models") or "shipped") if started else None),
        ("learning backend", ", ".join(results.get("backends", [])) or None),
        ("defer below", results.get("defer_below")),
        ("posterior", started.get("posterior_method")),
        ("run time", f"{results['seconds']:.0f} s" if "seconds" in results else None),
    ])
    # Table 1
    lines += ["## Table 1: the Sawyer's sort", "",
              f"Counts summed over {repeats} repeat(s); precision and recall of the sums with "
              "95% intervals from a two-level bootstrap (repeats, then onions), beside the "
              "paper's physical robot. TP: blemished onion binned, FP: good onion binned, TN: "
              "good onion left on the line, FN: blemished onion left on the line.", "",
              table(results), ""]
    rows = []
    for m in methods:
        r = results["methods"][m]
        rows.append({"label": m, **{k: r[k] for k in ("precision", "recall")},
                     **{k: r[k] for k in ("precision_ci", "recall_ci") if k in r},
                     "paper": PAPER_TABLE_1.get(m)})
        if m in results.get("deferring", {}):
            d = results["deferring"][m]
            rows.append({"label": f"{m}\ndeferring", **{k: d[k] for k in ("precision", "recall")},
                         **{k: d[k] for k in ("precision_ci", "recall_ci") if k in d}})
    lines += _pr_figure(folder, rows, title=f"demo: precision and recall per method "
                                            f"({repeats} repeat(s), 95% intervals)")
    if repeats > 1:
        lines += ["### Per repeat", "",
                  *_table(("repeat", "folder", "seed", "method", "TP", "FP", "TN", "FN",
                           "precision", "recall", "ILE", "undecided"),
                          ((k, f"`repeat_{k}/`", r.get("seed"), m, *(r[c] for c in CELLS),
                            _rate(r["precision"]), _rate(r["recall"]), _num(r.get("ile")),
                            r.get("undecided", "-"))
                           for k in range(repeats) for m in methods
                           for r in [results["methods"][m]["per_repeat"][k]])), ""]
    lines += _demo_calibration(folder, results)
    if "deferring" in results:
        lines += _demo_deferring(folder, results, methods, repeats)
    lines += _demo_learning(folder, results, methods, repeats)
    return lines


def _demo_calibration(folder: Path, results: dict) -> list[str]:
    lines = ["## Calibration: the observation model", "",
             "How often perception misreads what it sees, measured on held-out frames "
             "(`calibration/`); the learners' observation model is built from these counts.",
             "", *_table(("error rate", "value"), [
                 ("state: an unoccluded step's state misread",
                  _num(results.get("state_error_rate"))),
                 ("(state, action): its state or its action misread",
                  _num(results.get("pair_error_rate")))]), ""]
    backwards = results.get("sessions_read_backwards")
    if backwards:
        from onionsort.stages.calibrate import describe_session_swaps

        lines += [f"Held-out sessions: {describe_session_swaps(backwards)}.", ""]
    path = folder / "calibration" / "calibration.json"
    if path.is_file():
        cal = _read(path)
        metrics = cal.get("metrics", {})
        if "n_steps" in metrics:
            lines += [f"Measured on {metrics['n_steps']} held-out steps "
                      f"({metrics.get('n_occluded', 0)} occluded); occlusion recall "
                      f"{_num(metrics.get('occlusion_recall'))}, precision "
                      f"{_num(metrics.get('occlusion_precision'))}.", ""]
        if cal.get("accuracy"):
            lines += [*_table(("factor", "accuracy"),
                              ((k, _num(v)) for k, v in cal["accuracy"].items())), ""]
    lines += _image(folder, "calibration/confusion.png",
                    "confusion matrices, P(perceived | true) per factor")
    return lines


def _demo_deferring(folder: Path, results: dict, methods: list[str],
                    repeats: int) -> list[str]:
    """The second sort of the same line-ups, deferring to a person where the policy's
    posterior confidence is below the threshold."""
    lines = ["## Deferring", "",
             f"The Bayesian learners also sampled the posterior over rewards, and the Sawyer "
             f"sorted the same line-up(s) again, deferring an onion to a person where its "
             f"policy's confidence was below {results['defer_below']:g}. Precision and recall "
             "count the onions not deferred.", ""]
    rows = []
    for m in methods:
        d = results["deferring"].get(m)
        if d is None:
            continue
        risks = [r.get("posterior", {}).get("risk", {})
                 for r in results["methods"][m]["per_repeat"]]
        p_opt = ", ".join(_num(r.get("p_map_optimal")) for r in risks)
        rows.append((m, *(d[c] for c in CELLS), d.get("deferred", "-"),
                     _num(d.get("deferral_rate")), _rate(d["precision"], d.get("precision_ci")),
                     _rate(d["recall"], d.get("recall_ci")), p_opt or "-"))
    lines += [*_table(("method", "TP", "FP", "TN", "FN", "deferred", "deferral rate",
                       "precision", "recall", "P(policy optimal) per repeat"), rows), ""]
    if repeats > 1:
        lines += ["Per repeat:", "",
                  *_table(("repeat", "method", "TP", "FP", "TN", "FN", "deferred",
                           "precision", "recall"),
                          ((k, m, *(d[c] for c in CELLS), d.get("deferred", "-"),
                            _rate(d["precision"]), _rate(d["recall"]))
                           for k in range(repeats) for m in methods
                           if m in results["deferring"]
                           for d in [results["methods"][m]["per_repeat"][k]["deferring"]])),
                  ""]
    for k in range(repeats):
        base = "" if repeats == 1 else f"repeat_{k}/"
        for m in results["deferring"]:
            lines += _image(folder, f"{base}{m}/policy_confidence.png",
                            f"{m}{'' if repeats == 1 else f' (repeat {k})'}: posterior "
                            "confidence per state")
    return lines


def _demo_learning(folder: Path, results: dict, methods: list[str], repeats: int) -> list[str]:
    from onionsort.stages.learn import MODEL_FILE

    lines = ["## Learning", "",
             "The reward each method learned (its weights), its inverse learning error (ILE) "
             "against the sorter's true reward (0: the learned reward's optimal policy does "
             "as well as the sorter's under the true reward), and the learner's objective per "
             "iteration.", ""]
    rows, features = [], []
    for k in range(repeats):
        for m in methods:
            r = results["methods"][m]["per_repeat"][k]
            theta = r.get("theta") or {}  # behaviour cloning learns no reward: null
            features = features or list(theta)
            base = "" if repeats == 1 else f"repeat_{k}/"
            model = folder / base / m / MODEL_FILE
            n_iter = _read(model).get("n_iter", "-") if model.is_file() else "-"
            rows.append(((k,) if repeats > 1 else ()) + (
                m, _num(r.get("ile")), n_iter, _num(r.get("learn_seconds"), ".1f"),
                *(_num(theta.get(f), ".2f") for f in features)))
    header = (("repeat",) if repeats > 1 else ()) + ("method", "ILE", "iterations",
                                                      "seconds", *features)
    lines += [*_table(header, rows), ""]
    for k in range(repeats):
        base = "" if repeats == 1 else f"repeat_{k}/"
        for m in methods:
            lines += _image(folder, f"{base}{m}/learning_curve.png",
                            f"{m}{'' if repeats == 1 else f' (repeat {k})'}: learning curve")
    return lines


# --- experiment --------------------------------------------------------------------------


def _experiment(folder: Path) -> list[str]:
    summary = _read(folder / "summary.json")
    config = summary["config"]
    points = summary["points"]
    lines = _preamble("Experiment", folder, "`summary.json` and the sweep's plots")

    def listed(key):
        value = config.get(key)
        return ", ".join(map(str, value)) if isinstance(value, list) else value

    grid = config.get("points")
    bootstrap = summary.get("bootstrap", {})
    lines += _settings([
        ("domain", config.get("domain")),
        ("(occlusion, noise) points", ", ".join(f"({o:g}, {n:g})" for o, n in grid)
         if grid else None),
        ("methods", listed("methods")),
        ("batches per point", config.get("batches")),
        ("demonstrations per batch", listed("trajectories")),
        ("steps per demonstration", listed("length")),
        ("learner settings", listed("learners")),
        ("seed", config.get("seed")),
        ("trials per backend", ", ".join(f"{k}: {v}" for k, v in
                                         summary.get("trial_backends", {}).items()) or None),
        ("executor", f"{summary.get('executor')}, {summary.get('workers')} worker(s)"
         if "executor" in summary else None),
        ("intervals", f"{bootstrap.get('confidence', 0.95):.0%} {bootstrap.get('method')} "
                      f"({bootstrap.get('n_resamples')} resamples)" if bootstrap else None),
    ])
    lines += ["## Summary", "",
              "Per method and setting, the mean over the batches: the normalized ILE (percent "
              "of the expert's value lost by the learned reward's policy) and the rate of "
              "batches whose learned policy is exactly the expert's, with 95% bootstrap "
              "intervals over batches.", "",
              *_table(("method", "learner (beta)", "occlusion", "noise", "demos", "length",
                       "batches", "normalized ILE (%) [95% CI]", "exact-policy rate [95% CI]",
                       "ILE mean", "seconds"),
                      ((p["method"], f"{p['learner']} ({p['learner_beta']:.3g})",
                        f"{p['occlusion']:.2f}", f"{p['noise']:.2f}", p["trajectories"],
                        p["length"], p.get("batches", "-"),
                        _rate(p["normalized_ile_mean"], (p["normalized_ile_ci_low"],
                                                         p["normalized_ile_ci_high"]), ".3f"),
                        _rate(p["exact_policy_rate"], (p["exact_policy_ci_low"],
                                                       p["exact_policy_ci_high"])),
                        _num(p.get("ile_mean")), _num(p.get("seconds_mean")))
                       for p in points)), ""]
    figures = [line for name, caption in SWEEP_FIGURES
               for line in _image(folder, name, caption)]
    lines += ["## Plots", "", *(figures or ["The sweep wrote no plots (it varies no setting a "
                                            "plot is drawn against).", ""])]
    return lines


# --- learn and evaluate ------------------------------------------------------------------


def _learn(folder: Path) -> list[str]:
    from irl.learners.optimize import objective_curve
    from onionsort.stages.learn import CONFIDENCE_FILE, MODEL_FILE

    model = _read(folder / MODEL_FILE)
    in_demo = _demo_repeat(folder)
    confidence = _read(folder / CONFIDENCE_FILE) if (folder / CONFIDENCE_FILE).is_file() \
        else None
    sessions = model.get("sessions", [])
    lines = _preamble("Learning run", folder, "`model.json` and the files beside it")
    lines += _settings([
        ("method", model.get("method")),
        ("forward-backward backend", model.get("backend")),
        ("seed", in_demo.get("seed") if in_demo else None),
        ("sessions", len(sessions)),
        ("steps", f"{model.get('n_steps')} ({model.get('n_occluded')} occluded)"),
        ("observation model", f"`{model['observation_model']}`"
         if "observation_model" in model else None),
        ("calibrated state error rate", _num(model.get("state_error_rate"))),
        ("iterations", model.get("n_iter")),
        ("perception models", f"{len(model['model_mismatch_allowed'])} session(s) perceived "
                              "otherwise than the calibration was measured, allowed "
                              "(model.json's model_mismatch_allowed says how)"
         if model.get("model_mismatch_allowed") else None),
        ("posterior", f"{confidence['method']}, {confidence['n_samples']} samples"
         if confidence else None),
    ])
    ile = in_demo.get("ile") if in_demo else None
    lines += ["## Learned reward", "",
              *(_table(("feature", "weight"), ((k, _num(v, ".4f"))
                                               for k, v in model["theta"].items()))
                if model.get("theta") is not None else
                [f"None: {model.get('method')} clones the sorter's policy from its actions and "
                 "learns no reward; the policy below is its most probable action per state "
                 f"({len(model.get('unseen_states', []))} state(s) never seen, where it acts "
                 "at random)."]), "",
              (f"Inverse learning error against the sorter's true reward: {ile:.4f} (as "
               "recorded by the demo this run belongs to)." if ile is not None else
               "Inverse learning error: not recorded (a demo records it for the runs it "
               "learns)."), ""]
    lines += _policy(model, confidence)
    history = []
    if (folder / "learning_curve.json").is_file():
        history = json.loads((folder / "learning_curve.json").read_text())
    _, curve = objective_curve(history if isinstance(history, list) else [])
    lines += ["## Learning curve", "",
              (f"{len(curve)} evaluations of the objective; first {curve[0]:.3f}, best "
               f"{max(curve):.3f}." if curve else "The learner recorded no objective."), "",
              *_image(folder, "learning_curve.png", f"{model.get('method')}: learning curve")]
    if confidence:
        lines += _confidence(folder, confidence)
    rows = []
    for sub, title, label in (("", "Evaluation: the Sawyer's sort", "sort"),
                              ("deferring/", "Evaluation, deferring", "deferring")):
        if (folder / sub / "evaluation.json").is_file():
            e = _read(folder / sub / "evaluation.json")
            lines += _evaluation(e, title, level="##")
            rows.append({"label": f"{e.get('method') or 'policy'}\n{label}",
                         "precision": e["precision"], "recall": e["recall"]})
    if rows:
        lines += _pr_figure(folder, rows)
    return lines


def _policy(model: dict, confidence: dict | None) -> list[str]:
    policy = model.get("policy", [])
    conf = {row["state"]: row for row in confidence["states"]} if confidence else {}
    cloned = model.get("theta", {}) is None  # behaviour cloning: each action's probability
    header = ("state", "action") + (("confidence", "90% credible actions") if conf else ()) \
        + (("probability",) if cloned else ())
    rows = []
    for p in policy:
        row = conf.get(p["state"])
        extra = ((_num(row["confidence"].get(p["action"]), ".2f"),
                  ", ".join(row.get("credible_90", []))) if row else ("-", "-")) if conf else ()
        rows.append((p["state"], p["action"], *extra,
                     *((_num(p.get("probability"), ".2f"),) if cloned else ())))
    what = ("The cloned policy's most probable action" if cloned
            else "The greedy policy of the learned reward")
    return ["## Learned policy", "",
            f"{what}, {len(policy)} states.", "",
            "<details><summary>the action in every state</summary>", "",
            *_table(header, rows), "", "</details>", ""]


def _confidence(folder: Path, confidence: dict) -> list[str]:
    risk, diag = confidence.get("risk", {}), confidence.get("diagnostics", {})
    unsure = [row for row in confidence.get("states", [])
              if row["confidence"].get(row["map_action"], 0.0) < 0.9]
    r_hat = [v for v in diag.get("r_hat", []) if v is not None]
    lines = ["## Policy confidence (the posterior)", "",
             *_table(("quantity", "value"), [
                 ("P(the learned policy is optimal)", _num(risk.get("p_map_optimal"))),
                 ("expected ILE", _num(risk.get("expected_ile"), ".4f")),
                 ("expected normalized ILE (%)", _num(risk.get("expected_normalized_ile"))),
                 ("max R-hat", _num(max(r_hat), ".3f") if r_hat else "-"),
                 ("divergent transitions", diag.get("n_divergent", "-"))]), ""]
    if unsure:
        lines += [f"States where the learned action's confidence is below 0.9 "
                  f"({len(unsure)}):", "",
                  *_table(("state", "description", "action", "confidence",
                           "90% credible actions"),
                          ((r["state"], r.get("description", ""), r["map_action"],
                            _num(r["confidence"][r["map_action"]], ".2f"),
                            ", ".join(r.get("credible_90", []))) for r in unsure)), ""]
    else:
        lines += ["The learned action's confidence is at least 0.9 in every state.", ""]
    return [*lines, *_image(folder, "policy_confidence.png", "posterior confidence per state")]


def _evaluation(e: dict, title: str, *, level: str) -> list[str]:
    """Counts, precision and recall and deferral of an ``evaluation.json``'s document ``e``."""
    lines = [f"{level} {title}", "",
             *_table(("setting", "value"), [
                 (k, v) for k, v in (
                     ("policy", e.get("policy")), ("method", e.get("method")),
                     ("seed", e.get("seed")), ("difficulty", e.get("difficulty")),
                     ("inspection", e.get("inspection")),
                     ("views at most", e.get("inspection_views")),
                     ("every view", e.get("every_view")),
                     ("bins from P(blemished) >=", _num(e.get("threshold"), ".2f")
                      if e.get("threshold") is not None else None),
                     ("fusion", e.get("fusion")), ("defer below", e.get("defer_below")))
                 if v is not None]), "",
             *_table(("onions", "TP", "FP", "TN", "FN", "precision", "recall", "undecided",
                      "deferred", "deferral rate", "steps", "views taken"),
                     [(e.get("n_onions", "-"), *(e[c] for c in CELLS), _rate(e["precision"]),
                       _rate(e["recall"]), e.get("undecided", "-"), e.get("deferred", "-"),
                       _num(e.get("deferral_rate")), e.get("n_steps", "-"),
                       e.get("views_taken", "-"))]), ""]
    if e.get("deferred"):
        lines += ["Precision and recall count the onions not deferred.", ""]
    return lines


def _evaluate(folder: Path) -> list[str]:
    e = _read(folder / "evaluation.json")
    lines = _preamble("Evaluation", folder, "`evaluation.json`")
    lines += _evaluation(e, "The Sawyer's sort", level="##")
    rows = [{"label": e.get("method") or e.get("policy") or "policy",
             "precision": e["precision"], "recall": e["recall"]}]
    lines += _pr_figure(folder, rows, title=f"{rows[0]['label']}: precision and recall "
                                            f"({e.get('n_onions', '?')} onions)")
    return lines


_WRITERS = {"demo": _demo, "experiment": _experiment, "learn": _learn,
            "evaluate": _evaluate}
