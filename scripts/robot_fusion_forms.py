"""Forms of the robot's fused calibration: fitted on held-out robot onions, measured on others.

Each robot onion's fused evidence ``E`` (the robot's inspection classifier on the detector's
crops of its first ``--views`` views, fused at prior 1/2 and uncalibrated, as ``onionsort train
robot-fusion`` reads it) is read once per dataset. Each candidate form maps ``E`` to the
calibrated log-odds, keeps its sign (every call at the prior threshold stays) and is monotone;
each is fitted on the ``--fit`` datasets together by log-loss against Platt's targets of each
side of ``E = 0`` (the product's forms by :func:`onionsort.stages.inspection.fit_side_map`, as
``train robot-fusion`` fits them), then measured on each ``--measure`` dataset: ECE (15 bins)
beside the median and 90th percentile of what a perfectly calibrated model shows by chance on
the same onions (:func:`perception.fusion.calibration_within_chance`), and the share of right
calls.

Forms (parameters): ``slopes`` (2, :data:`perception.fusion.CALIBRATION_FORMS`), ``log`` (2,
likewise), ``powers`` (4, likewise: ``-low |E|^a`` below 0, ``high E^b`` above), ``power`` (3:
``powers`` with ``a = b``), ``jump`` (3: ``low E`` below 0, ``c + high E`` above).
``--calibration LOW,HIGH[,FORM[,A,B]]`` measures a given calibration too (a shipped one);
``--forms ''`` with it measures given calibrations alone; ``--pool`` measures the sets pooled
too.

Example
-------
    python scripts/robot_fusion_forms.py --fit runs/fit-clean --fit runs/fit-hard \
        --measure runs/d9105 --cache runs/E --calibration 2.6205,0.1503 \
        --calibration 4.6186,1.3819,log
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from onionsort.stages.inspection import fit_side_map
from perception.fusion import CALIBRATION_FORMS, calibration_within_chance, check_calibration

FORMS = {"slopes": 2, "log": 2, "powers": 4, "power": 3, "jump": 3}


def read_evidence(data: Path, models: Path | None, views: int, cache: Path | None) -> dict:
    """``E`` (noisy-or), class ``y`` and level of each robot onion of ``data`` (all splits)."""
    name = f"{data.name}.npz"
    if cache is not None and (cache / name).is_file():
        z = np.load(cache / name)
        return {"E": z["E"], "y": z["y"], "level": z["level"]}
    import torch

    from onionsort.stages.inspection import inspection_views
    from onionsort.stages.models import PerceptionModels
    from perception.fusion import log_odds

    torch.set_num_threads(2)
    loaded = PerceptionModels.load(models, "cpu")
    clf = loaded.robot_inspection or loaded.inspection
    got = inspection_views(data, "all", detector=loaded.detector_for("robot"),
                           allow_empty=True)
    got = got.subset((got.source == "robot") & got.found.astype(bool) & (got.view < views))
    p = clf.calibrated(clf.logits(got.crops), "noisy-or")
    groups = defaultdict(list)
    for i, key in enumerate(got.onion):
        groups[key].append(i)
    keys = sorted(groups)
    args = {"prior": 0.5, "train_prior": clf._train_prior("noisy-or"),
            "visibility": clf.visibility}
    out = {"E": np.array([log_odds(p[groups[k]], "noisy-or", **args) for k in keys]),
           "y": np.array([got.classes[groups[k][0]] for k in keys], float),
           "level": np.array([got.level[groups[k][0]] for k in keys])}
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        tmp = cache / f"{data.name}.partial.npz"
        np.savez(tmp, **out)
        tmp.replace(cache / name)
    return out


def mapped(form: str, E: np.ndarray, q) -> np.ndarray:
    """The calibrated log-odds (prior 1/2) of evidence ``E`` under ``form`` and ``q``."""
    size = np.abs(E)
    if form == "slopes":
        return np.where(E < 0, -q[0], q[1]) * size
    if form == "log":
        return np.where(E < 0, -q[0], q[1]) * np.log1p(size)
    if form == "power":
        return np.where(E < 0, -q[0], q[1]) * size ** q[2]
    if form == "jump":
        return np.where(E < 0, -q[0] * size, q[2] + q[1] * size)
    return np.where(E < 0, -q[0] * size ** q[2], q[1] * size ** q[3])  # powers


def _targets(E: np.ndarray, y: np.ndarray) -> np.ndarray:
    t = np.empty(len(E))
    for side in (E < 0, E >= 0):
        n_pos, n_neg = y[side].sum(), (1 - y[side]).sum()
        t[side] = np.where(y[side] == 1, (n_pos + 1) / (n_pos + 2), 1 / (n_neg + 2))
    return t


def fit(form: str, E: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The parameters of ``form`` fitted on evidence ``E`` and classes ``y``."""
    if form in CALIBRATION_FORMS:
        fitted = fit_side_map(E, y, form)
        return np.array([*fitted[:2], *fitted[3:]])
    t = _targets(E, y)

    def loss(q) -> float:
        z = mapped(form, E, q)
        return float(np.mean(np.logaddexp(0.0, z) - t * z))

    if form == "power":  # slopes fitted per side for each k; k by a bounded search
        def at(k: float) -> np.ndarray:
            s = np.sign(E) * np.abs(E) ** k
            return np.array([*fit_side_map(s, y)[:2], k])

        k = float(np.exp(minimize_scalar(lambda a: loss(at(float(np.exp(a)))),
                                         bounds=(np.log(0.02), np.log(2.0)),
                                         method="bounded", options={"xatol": 1e-4}).x))
        return at(k)
    rng = np.random.default_rng(0)  # jump: Nelder-Mead on the logs, from 20 starts
    best = min((minimize(lambda a: loss(np.exp(a)), rng.normal(0, 1, FORMS[form]),
                         method="Nelder-Mead",
                         options={"maxiter": 20000, "xatol": 1e-8, "fatol": 1e-12})
                for _ in range(20)), key=lambda r: r.fun)
    return np.exp(best.x)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fit", type=Path, action="append", required=True)
    ap.add_argument("--measure", type=Path, action="append", required=True)
    ap.add_argument("--models", type=Path, default=None)
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--forms", default=",".join(FORMS))
    ap.add_argument("--calibration", action="append", default=[],
                    help="LOW,HIGH[,FORM[,A,B]]: a given calibration measured too "
                         "(repeatable)")
    ap.add_argument("--pool", action="store_true",
                    help="measure the --measure datasets pooled too")
    ap.add_argument("--cache", type=Path, default=None,
                    help="folder keeping each dataset's evidence (DATASET-NAME.npz)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    forms = [f for f in a.forms.split(",") if f]
    unknown = sorted(set(forms) - set(FORMS))
    if unknown:
        raise SystemExit(f"unknown forms {unknown}; the forms are {list(FORMS)}")
    fitted = [read_evidence(d, a.models, a.views, a.cache) for d in a.fit]
    E = np.concatenate([f["E"] for f in fitted])
    y = np.concatenate([f["y"] for f in fitted])
    print(f"fitted on {len(y)} onions ({int(y.sum())} blemished)")
    params = {form: (form, fit(form, E, y)) for form in forms}
    for i, text in enumerate(a.calibration):
        try:
            given = check_calibration(text.split(","))
        except ValueError as exc:
            raise SystemExit(f"--calibration {text}: {exc}") from None
        params[f"given {i + 1}"] = (given[2], np.array([*given[:2], *given[3:]]))
    measured = {str(d): read_evidence(d, a.models, a.views, a.cache) for d in a.measure}
    if a.pool:
        measured["pooled"] = {key: np.concatenate([m[key] for m in measured.values()])
                              for key in ("E", "y", "level")}
    out = {}
    for name, (form, q) in params.items():
        row = {"form": form, "params": q.tolist()}
        print(f"{name} ({form}): {np.round(q, 4).tolist()}")
        for d, m in measured.items():
            p = 1.0 / (1.0 + np.exp(-mapped(form, m["E"], q)))
            check = calibration_within_chance(p, m["y"])
            calls = float(np.mean((p >= 0.5) == (m["y"] == 1)))
            row[d] = {**check, "calls": calls}
            print(f"    {d}: ECE {check['ece']:.4f}, by chance median "
                  f"{check['chance_median']:.4f}, 90th percentile {check['chance_quantile']:.4f}"
                  f" ({check['onions']} onions; within: {check['within']}); calls right "
                  f"{calls:.3f}")
        out[name] = row
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
