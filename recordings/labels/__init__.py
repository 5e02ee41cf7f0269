"""Labelled data: datasets on disk for training and calibrating perception, and the formats
annotation tools read and write.

- :mod:`~recordings.labels.dataset`: the dataset layout, its writer and readers;
- :mod:`~recordings.labels.annotated`: labelled images as the tools hold them;
- :mod:`~recordings.labels.coco`, :mod:`~recordings.labels.yolo`,
  :mod:`~recordings.labels.labelstudio`: the tools' formats;
- :mod:`~recordings.labels.states_csv`, :mod:`~recordings.labels.lineups_csv`: state labels and
  a robot's line-ups as CSV.
"""
