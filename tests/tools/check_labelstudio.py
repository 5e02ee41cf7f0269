"""Validate a Label Studio task file and its labelling interface with Label Studio's own SDK.

    python tests/tools/check_labelstudio.py LABELING_CONFIG.xml TASKS.json

Prints one JSON object: ``config`` (the interface's errors, [] where it validates), ``tasks``
(per task: whether the SDK accepts its data for the interface) and ``predictions`` (per task:
the errors of each of its predictions). Run with the SDK on the path (``tests.tools``).
"""

import json
import sys
from pathlib import Path

from label_studio_sdk.label_interface import LabelInterface

config_path, tasks_path = sys.argv[1:3]
interface = LabelInterface(Path(config_path).read_text())
try:
    interface.validate()
    config_errors = []
except Exception as exc:  # the SDK's validation error names what is wrong
    config_errors = [str(exc)]
tasks = json.loads(Path(tasks_path).read_text())
# validate_task(task) checks a task's data against the interface's variables; with
# predictions in it, SDK 2.1.2 calls validate_prediction() without the prediction, so each
# prediction is validated on its own
print(json.dumps({
    "config": config_errors,
    "tasks": [interface.validate_task({"data": t["data"]}) for t in tasks],
    "predictions": [[interface.validate_prediction(p, return_errors=True)
                     for p in t.get("predictions", [])] for t in tasks],
}))
