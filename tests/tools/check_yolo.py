"""Read a YOLO dataset with Ultralytics' own loader, as its trainer does.

    python tests/tools/check_yolo.py DATA.yaml

Prints one JSON object: ``names`` (``check_det_dataset``'s class names) and, for each split
the YAML names, the loader's scan (``found``, ``missing``, ``empty``, ``corrupt`` label files,
``images``) and the boxes it read per class. Run with Ultralytics on the path
(``tests.tools``), ``YOLO_OFFLINE=1`` and ``YOLO_CONFIG_DIR`` set.
"""

import json
import sys
from collections import Counter
from pathlib import Path

from ultralytics.data import YOLODataset
from ultralytics.data.utils import check_det_dataset, load_dataset_cache_file

data = check_det_dataset(sys.argv[1], autodownload=False)
out = {"names": data["names"]}
for split in ("train", "val", "test"):
    if not data.get(split):
        continue
    dataset = YOLODataset(img_path=data[split], data=data, task="detect", augment=False,
                          imgsz=320, batch_size=4)
    cache = load_dataset_cache_file(Path(dataset.label_files[0]).parent.with_suffix(".cache"))
    found, missing, empty, corrupt, total = cache["results"]
    boxes = Counter(int(c) for label in dataset.labels for c in label["cls"].ravel())
    out[split] = {"found": found, "missing": missing, "empty": empty, "corrupt": corrupt,
                  "images": len(dataset.labels), "total": total,
                  "boxes": {str(k): v for k, v in sorted(boxes.items())}}
print(json.dumps(out))
