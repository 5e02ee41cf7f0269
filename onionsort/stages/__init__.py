"""The pipeline's stages: one module each, a frozen config plus a function that runs it.

=================  ===========================  ==========================================
stage              config                       function
=================  ===========================  ==========================================
record             :class:`RecordConfig`        :func:`record` -> session paths
import             :class:`ImportConfig`        :func:`import_video` -> a sensor-only session
export             :class:`ExportConfig`        :func:`export_session` -> a rosbag2 folder
dataset            :class:`DatasetConfig`       :func:`make_dataset`
train              ``ClassifierTrainConfig``,   ``train_state_classifier``, ``train_detector``
                   ``DetectorTrainConfig``      (in :mod:`onionsort.stages.train`)
perceive           :class:`PerceiveConfig`      :func:`perceive`
calibrate          :class:`CalibrateConfig`     :func:`calibrate`, :func:`eval_perception`
compare-perception ``PerceptionCompareConfig``  :func:`compare_perception`: a candidate's
                                                figures against a baseline's
learn              :class:`LearnConfig`         :func:`learn` -> model.json content
evaluate           :class:`EvaluateConfig`      :func:`evaluate` (a simulated or a recorded
                                                line-up: :mod:`onionsort.stages.lineup`)
score              :class:`ScoreConfig`         :func:`score` -> a tally's counts
suggest            :class:`SuggestConfig`       :func:`suggest` -> states worth a demonstration
demo               :class:`DemoConfig`          :func:`demo` (composes the stages above)
experiment         :class:`ExperimentConfig`    :func:`run_experiment` (synthetic sweeps)
eval-posterior     ``PosteriorEvalConfig``      ``eval_posterior`` (in
                                                :mod:`onionsort.stages.eval_posterior`)
report             :class:`ReportConfig`        :func:`report` -> ``RUN/report.md``
=================  ===========================  ==========================================

The CLI's commands parse arguments into these configs and call the function; scripts do the
same. Each function logs its resolved config once.
"""

from onionsort.stages.calibrate import (
    CalibrateConfig,
    PerceptionEvalConfig,
    calibrate,
    eval_perception,
)
from onionsort.stages.compare_perception import PerceptionCompareConfig, compare_perception
from onionsort.stages.dataset import DatasetConfig, make_dataset
from onionsort.stages.demo import DemoConfig, demo
from onionsort.stages.evaluate import EvaluateConfig, evaluate
from onionsort.stages.experiment import ExperimentConfig, run_experiment
from onionsort.stages.export import ExportConfig, export_session
from onionsort.stages.import_video import ImportConfig, import_video, list_bag
from onionsort.stages.learn import LearnConfig, learn
from onionsort.stages.lineup import ScoreConfig, score
from onionsort.stages.models import PerceptionModels
from onionsort.stages.perceive import PerceiveConfig, perceive
from onionsort.stages.record import RecordConfig, record
from onionsort.stages.report import ReportConfig, report
from onionsort.stages.suggest import SuggestConfig, suggest

__all__ = [
    "CalibrateConfig",
    "DatasetConfig",
    "DemoConfig",
    "EvaluateConfig",
    "ExperimentConfig",
    "ExportConfig",
    "ImportConfig",
    "LearnConfig",
    "PerceiveConfig",
    "PerceptionCompareConfig",
    "PerceptionEvalConfig",
    "PerceptionModels",
    "RecordConfig",
    "ReportConfig",
    "ScoreConfig",
    "SuggestConfig",
    "calibrate",
    "compare_perception",
    "demo",
    "eval_perception",
    "evaluate",
    "export_session",
    "import_video",
    "learn",
    "list_bag",
    "make_dataset",
    "perceive",
    "record",
    "report",
    "run_experiment",
    "score",
    "suggest",
]
