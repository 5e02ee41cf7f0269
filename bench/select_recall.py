"""How well ``label select`` finds perception's mistakes, on recorded sessions that carry the
truth (which the selection itself never reads).

For the sessions given, perception runs on every step (as ``label select`` runs it); a step is
*wrong* where its occluded call, or on a truly unoccluded step its state (onion, end effector,
prediction), differs from the truth. Prints how many steps are wrong, how many of the steps
that ``label select --frames N`` takes are, the ratio of the two rates, and each wrong step it
leaves out with its uncertainty and what was wrong.

Example
-------
    onionsort record --sessions 6 --steps-per-session 20 --difficulty paper --seed 6122 \\
        --out runs/sel-6122
    python bench/select_recall.py runs/sel-6122/*.mcap --frames 60
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def measure(paths: list[Path], frames: int, models) -> dict:
    """The counts printed by this script (see the module docstring), as a dict."""
    from irl.domains.onion_sorting import SORTING_TASK as task
    from onionsort.stages.label_select import _choose, step_uncertainties
    from recordings.session.reader import open_session

    wrong, what, scores = {}, {}, []
    for k, path in enumerate(paths):
        steps = open_session(path).step_frames()
        seen = models.perceive([([f.color for f in st], [f.depth for f in st],
                                 [f.inspection if f.inspection_png is not None else None
                                  for f in st]) for st in steps])
        scores.append(step_uncertainties(seen))
        for t, (st, guess) in enumerate(zip(steps, seen, strict=True)):
            truth = st[0].state
            bad = [] if guess.occluded == truth["occluded"] else ["occluded"]
            if not truth["occluded"] and not guess.occluded:
                bad += [f for f in task.factor_names
                        if task.value_name(f, getattr(guess, f)) != truth[f]]
            wrong[k, t] = bool(bad)
            what[k, t] = bad
    taken = set(_choose(scores, models.frames_per_step, frames))
    n_wrong = sum(wrong.values())
    hit = sum(wrong[s] for s in taken)
    rate, rate_taken = n_wrong / len(wrong), hit / len(taken)
    return {"steps": len(wrong), "wrong": n_wrong, "taken": len(taken), "wrong_taken": hit,
            "ratio": rate_taken / rate if rate else None,
            "missed": [{"session": k, "step": t, "uncertainty": round(scores[k][t], 4),
                        "wrong": what[k, t]}
                       for (k, t), w in sorted(wrong.items()) if w and (k, t) not in taken]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("sessions", type=Path, nargs="+", help="recorded sessions (.mcap)")
    p.add_argument("--frames", type=int, default=60, help="label select's --frames (60)")
    p.add_argument("--models", type=Path, default=None, help="default: the shipped models")
    args = p.parse_args(argv)
    from onionsort.stages.models import PerceptionModels

    r = measure(args.sessions, args.frames, PerceptionModels.load(args.models, "cpu"))
    print(f"{r['wrong']} of {r['steps']} steps wrong ({r['wrong'] / r['steps']:.3f}); "
          f"{r['wrong_taken']} of the {r['taken']} taken ({r['wrong_taken'] / r['taken']:.3f})"
          + ("" if r["ratio"] is None else f", {r['ratio']:.1f} times as often"))
    for m in r["missed"]:
        print("  missed: " + json.dumps(m))
    return 0


if __name__ == "__main__":
    sys.exit(main())
