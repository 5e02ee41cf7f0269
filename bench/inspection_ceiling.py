"""What a perfect inspection would buy: sessions read backwards with views read from the truth.

A session is *read backwards* when more than half of its reads of the onion's class are the
other class (:func:`onionsort.stages.calibrate.session_swaps`). Those reads come from the
sorter's inspection views, fused as they come
(:func:`state_abstraction.perceive.track_predictions`). This script perceives a dataset four
ways, the state classifier and the fusion unchanged, and prints, for each, the prediction
factor and the sessions read backwards:

- **the models**: the shipped ones (or ``--models``), as ``onionsort eval-perception`` does;
- **a perfect rot detector**: each view of the sorter's reads "rot" exactly where the
  renderer's label says it shows rot (at least :data:`perception.inspection.ROT_SHARE` of the
  onion's visible pixels), "none" where it shows none, and "unclear" (probability 1/2) where it
  shows a trace below that. A blemished onion whose rot faces away or lies under the hand in
  every view is still read good: this is the ceiling of any classifier of the views;
- **a detector of any rot pixel**: the same, with a trace below that share read "rot" too
  (one rot pixel is enough; past any camera's resolution at ``hard``'s contrast and noise);
- **a perfect class reader**: each view says the onion's class, as if rot were always in view.

The gap between the models and the perfect rot detector is what a better classifier can win;
the gap between the rot detector and the class reader is what the views do not show.

Example
-------
    onionsort dataset --frames 1500 --robot-onions 0 --seed 7501 --difficulty hard \
        --out runs/h7501
    python bench/inspection_ceiling.py --data runs/h7501
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from onionsort.stages.calibrate import measure_perception
from onionsort.stages.inspection import _held_onion
from onionsort.stages.models import PerceptionModels
from perception.inspection import Inspector, _digest, rot_label
from recordings.labels.dataset import read_split, split_names

#: what a view read from the truth says, per reader: by its rot label (1 rot, 0 none, -1 a
#: trace) for the rot detectors, by the onion's class (0 good, 1 blemished) for the class reader
_READ = {"rot": {1: 0.99, 0: 0.01, -1: 0.5}, "trace": {1: 0.99, 0: 0.01, -1: 0.99},
         "class": {0: 0.01, 1: 0.99}}


def truth_tables(root: Path, split: str) -> dict[str, dict[str, float | None]]:
    """Per reader (``"rot"``, ``"trace"``, ``"class"``; :data:`_READ`), per inspection view of
    ``split`` (by its digest): the probability that perfect reader gives it, None where it
    shows no onion. One pass over the views."""
    tables: dict[str, dict[str, float | None]] = {mode: {} for mode in _READ}
    for name in split_names(split):
        for frame in read_split(root, name, view="inspection"):
            rec, digest = frame.record, _digest([frame.color])
            k = _held_onion(rec)
            if k is None:
                for table in tables.values():
                    table[digest] = None
                continue
            rot = rec.get("rot_pixels")
            if rot is None:
                raise SystemExit(f"{root} records no rot pixels; render it again with "
                                 "`onionsort dataset`")
            blemished = bool(rec["classes"][k])
            visible = (rec.get("visible_pixels") or [0] * len(rec["boxes"]))[k]
            label = {"class": int(blemished), "rot": rot_label(rot[k], visible, blemished)}
            label["trace"] = label["rot"]
            for mode, table in tables.items():
                table[digest] = _READ[mode][label[mode]]
    return tables


class TruthInspector(Inspector):
    """An :class:`~perception.inspection.Inspector` whose views are read from ``table``."""

    def __init__(self, base: Inspector, table: dict[str, float | None]) -> None:
        super().__init__(base.detector, base.classifier, rule=base.rule,
                         threshold=base.threshold, prior=base.prior, values=base.values)
        self.table = table

    def view_probabilities(self, views):
        try:
            return [self.table[_digest([v])] for v in views]
        except KeyError:
            raise SystemExit("a view of the sessions is not among the dataset's inspection "
                             "views") from None


@dataclasses.dataclass
class TruthModels(PerceptionModels):
    """The models, with the sorter's inspection views read from ``table``."""

    table: dict = dataclasses.field(default_factory=dict)

    @classmethod
    def reading(cls, models: PerceptionModels, table: dict) -> TruthModels:
        """``models`` (loaded), their sorter's views read from ``table``."""
        return cls(**{f.name: getattr(models, f.name) for f in dataclasses.fields(models)},
                   table=table)

    def inspector(self, **kwargs):
        return TruthInspector(super().inspector(**kwargs), self.table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="a dataset folder")
    parser.add_argument("--split", default="all")
    parser.add_argument("--models", type=Path, default=None,
                        help="models folder (default: the shipped models)")
    args = parser.parse_args(argv)
    models = PerceptionModels.load(args.models, "cpu")
    tables = truth_tables(args.data, args.split)
    rows = [("the models", models)] + [
        (label, TruthModels.reading(models, tables[mode]))
        for label, mode in (("a perfect rot detector", "rot"),
                            ("a detector of any rot pixel", "trace"),
                            ("a perfect class reader", "class"))]
    print(f"{args.data} ({args.split}): the sorter's views read by")
    print(f"  {'reader':<29}{'prediction':>12}{'after 1st insp.':>17}{'read backwards':>16}")
    for label, m in rows:
        _, metrics = measure_perception(m, args.data, args.split)
        swaps = metrics["session_swaps"]
        after = metrics["prediction_after_first_inspection"]
        print(f"  {label:<29}{metrics['accuracy']['prediction']:>12.3f}"
              f"{'-' if after is None else f'{after:.3f}':>17}"
              f"{swaps['swapped']:>9d} of {swaps['sessions']:<3d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
