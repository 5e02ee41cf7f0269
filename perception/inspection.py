"""The inspection classifier: is the onion held up to the inspection camera blemished?

Layouts: views ``rgb[v, u, c]`` (H, W, 3) uint8; boxes ``(x_min, y_min, x_max, y_max)`` in
pixels; crops ``crop[v, u, c]`` (S, S, 3) uint8, batched as ``x[n, c, v, u]`` float; logits and
probabilities ``(N,)`` for the class *blemished*.

The detector finds the onion (:class:`perception.Detector`, its best box of either class); a
small residual CNN (:class:`InspectionNet`) reads a square crop around it and gives one logit.
A temperature fitted on validation views (:func:`fit_temperature`) turns the logits into
calibrated probabilities, and :class:`Inspector` fuses an onion's views into one probability
(:mod:`perception.fusion`) and calls it blemished at the cost threshold.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import nn

from perception.checkpoint import load_checkpoint, save_checkpoint
from perception.fusion import FUSION_RULES, check_calibration, fuse, settled

__all__ = [
    "CROP_MARGIN",
    "CROP_SIZE",
    "INSPECTION_SCORE",
    "ROT_SHARE",
    "InspectionClassifier",
    "InspectionNet",
    "InspectionNetConfig",
    "InspectionVerdict",
    "Inspector",
    "crop_onion",
    "fit_platt",
    "fit_temperature",
    "rot_label",
]

CROP_SIZE = 64
"""Side of the square crop the network reads (pixels)."""
CROP_MARGIN = 0.15
"""Context around the onion's box, as a share of its longer side on each side."""
INSPECTION_SCORE = 0.2
"""Minimum detector score for an onion in an inspection view to count as found."""
ROT_SHARE = 0.01
"""A view shows rot when at least this share of the onion's visible pixels do."""
_MEAN, _STD = 0.5, 0.25


def rot_label(rot_pixels: int | None, visible_pixels: int, blemished: bool) -> int:
    """What a view is labelled for training: 1 if it shows rot (at least :data:`ROT_SHARE` of
    the onion's visible pixels), 0 if it shows none, -1 if it shows a trace below that (a
    sliver at the rim: unclear, left out). Without a measurement of the rot (``rot_pixels``
    None) the onion's class stands in."""
    if rot_pixels is None:
        return int(bool(blemished))
    if rot_pixels <= 0:
        return 0
    return 1 if rot_pixels >= ROT_SHARE * max(int(visible_pixels), 1) else -1


def crop_onion(rgb: np.ndarray, box, size: int = CROP_SIZE, margin: float = CROP_MARGIN,
               *, shift=(0.0, 0.0), scale: float = 1.0) -> np.ndarray:
    """The square crop (size, size, 3) uint8 around ``box`` in ``rgb`` (H, W, 3).

    The window is centred on the box (moved by ``shift`` times its side, for augmentation),
    its side ``scale * (1 + 2 margin)`` times the box's longer side; parts outside the image
    repeat its border. A window larger than the crop is shrunk by area averaging (the noise of
    a sharp view averages out), a smaller one enlarged bilinearly.
    """
    x0, y0, x1, y1 = (float(v) for v in box)
    side = max(x1 - x0, y1 - y0, 2.0) * (1 + 2 * margin) * scale
    n = max(round(side), 2)
    lo_x = round((x0 + x1) / 2 + shift[0] * side - n / 2)
    lo_y = round((y0 + y1) / 2 + shift[1] * side - n / 2)
    h, w = rgb.shape[:2]
    pad = max(0, -lo_x, -lo_y, lo_x + n - w, lo_y + n - h)
    src = np.ascontiguousarray(rgb)
    if pad:
        src = cv2.copyMakeBorder(src, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    window = src[lo_y + pad:lo_y + pad + n, lo_x + pad:lo_x + pad + n]
    interp = cv2.INTER_AREA if n > size else cv2.INTER_LINEAR
    return cv2.resize(window, (size, size), interpolation=interp)


def to_tensor(crops: Sequence[np.ndarray]) -> torch.Tensor:
    """Crops (S, S, 3) uint8 as a batch ``x[n, 3, S, S]`` float32 in [0, 1]."""
    x = torch.from_numpy(np.stack([np.asarray(c) for c in crops])).permute(0, 3, 1, 2)
    return x.float() / 255.0


@dataclass(frozen=True)
class InspectionNetConfig:
    """The network's shape: crop side, channels of the first stage (doubling per stage, three
    stages of stride 2 after the stem), and dropout before the last layer."""

    size: int = CROP_SIZE
    width: int = 24
    dropout: float = 0.2

    def __post_init__(self) -> None:
        if self.size < 16 or self.size % 8:
            raise ValueError(f"size must be a multiple of 8, >= 16; got {self.size}")
        if self.width < 4:
            raise ValueError(f"width must be >= 4; got {self.width}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1); got {self.dropout}")


def _conv(c_in: int, c_out: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False),
                         nn.BatchNorm2d(c_out), nn.SiLU(inplace=True))


class _Residual(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.body = nn.Sequential(_conv(c, c), nn.Conv2d(c, c, 3, 1, 1, bias=False),
                                  nn.BatchNorm2d(c))
        self.act = nn.SiLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(x + self.body(x))


class InspectionNet(nn.Module):
    """A small residual CNN: crop ``x[n, 3, S, S]`` (in [0, 1]) -> logit ``[n]`` of *blemished*.

    A stem at full resolution (a faint rot patch is a few pixels of a crop), three stages of a
    strided convolution and a residual block, global average and max pooling (a blemish
    anywhere on the onion counts), dropout and one linear unit.
    """

    def __init__(self, config: InspectionNetConfig | None = None) -> None:
        super().__init__()
        config = InspectionNetConfig() if config is None else config
        self.config = config
        w = config.width
        layers: list[nn.Module] = [_conv(3, w)]
        c = w
        for k in range(3):
            c_out = w * 2 ** k
            layers += [_conv(c, c_out, 2), _Residual(c_out)]
            c = c_out
        self.features = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.Dropout(config.dropout), nn.Linear(2 * c, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        f = self.features((x - _MEAN) / _STD)
        pooled = torch.cat([f.mean(dim=(2, 3)), f.amax(dim=(2, 3))], dim=1)
        return self.head(pooled).squeeze(1)


def fit_temperature(logits: np.ndarray, labels: np.ndarray, weights=None, *,
                    max_iter: int = 50, tol: float = 1e-10) -> float:
    """The temperature ``T > 0`` minimising the (``weights``-weighted) negative
    log-likelihood of ``labels`` (N,) under ``sigmoid(logits / T)`` (Guo et al., 2017).

    The loss is convex in ``w = 1 / T``; Newton's method on ``w`` from 1, halving a step that
    would leave ``[0.01, 100]`` or raise the loss, stops when a step changes ``w`` by less than
    ``tol`` and warns after ``max_iter`` steps. (Logits that say nothing would send ``T`` to
    infinity; it stops at 100, every probability near 1/2.)
    """
    z, y = np.asarray(logits, float).ravel(), np.asarray(labels, float).ravel()
    if z.size == 0 or z.shape != y.shape:
        raise ValueError(f"logits and labels must be non-empty and of one length; got "
                         f"{z.size} and {y.size}")
    c = np.ones_like(z) if weights is None else np.asarray(weights, float).ravel()
    c = c / c.sum()

    def loss(w: float) -> float:
        s = w * z
        return float(np.sum(c * (np.logaddexp(0.0, s) - y * s)))

    w = 1.0
    for _ in range(max_iter):
        sig = 1.0 / (1.0 + np.exp(-w * z))
        grad = float(np.sum(c * (sig - y) * z))
        hess = float(np.sum(c * sig * (1 - sig) * z * z)) + 1e-12
        step = grad / hess
        while not 0.01 <= w - step <= 100 or loss(w - step) > loss(w) + 1e-15:
            step /= 2
            if abs(step) < tol:
                break
        w -= step
        if abs(step) < tol:
            break
    else:
        import warnings

        warnings.warn(f"fit_temperature: Newton's method did not converge in {max_iter} "
                      "steps", RuntimeWarning, stacklevel=2)
    return float(1.0 / w)


def fit_platt(logits: np.ndarray, labels: np.ndarray, weights=None, *, max_iter: int = 50,
              tol: float = 1e-10) -> tuple[float, float]:
    """``(a, b)`` minimising the (``weights``-weighted) negative log-likelihood of ``labels``
    (N,) under ``sigmoid(a logits + b)`` (Platt scaling), by Newton's method from ``(1, 0)``
    with step halving; warns after ``max_iter`` steps.

    As in Platt (1999), the targets are ``(n+ + 1) / (n+ + 2)`` and ``1 / (n- + 2)`` rather
    than 1 and 0 (``n+``, ``n-`` the counts of each class), so that separable logits give a
    finite slope.
    """
    z, y = np.asarray(logits, float).ravel(), np.asarray(labels, float).ravel()
    if z.size == 0 or z.shape != y.shape:
        raise ValueError(f"logits and labels must be non-empty and of one length; got "
                         f"{z.size} and {y.size}")
    n_pos, n_neg = float(np.sum(y > 0.5)), float(np.sum(y <= 0.5))
    y = np.where(y > 0.5, (n_pos + 1) / (n_pos + 2), 1 / (n_neg + 2))
    c = np.ones_like(z) if weights is None else np.asarray(weights, float).ravel()
    c = c / c.sum()
    x = np.stack([z, np.ones_like(z)], axis=1)

    def loss(theta: np.ndarray) -> float:
        s = x @ theta
        return float(np.sum(c * (np.logaddexp(0.0, s) - y * s)))

    theta = np.array([1.0, 0.0])
    for _ in range(max_iter):
        sig = 1.0 / (1.0 + np.exp(-(x @ theta)))
        grad = x.T @ (c * (sig - y))
        hess = (x * (c * sig * (1 - sig))[:, None]).T @ x + 1e-9 * np.eye(2)
        step = np.linalg.solve(hess, grad)
        while loss(theta - step) > loss(theta) + 1e-15 and np.abs(step).max() > tol:
            step = step / 2
        theta = theta - step
        if np.abs(step).max() < tol:
            break
    else:
        import warnings

        warnings.warn(f"fit_platt: Newton's method did not converge in {max_iter} steps",
                      RuntimeWarning, stacklevel=2)
    return float(theta[0]), float(theta[1])


@dataclass(frozen=True)
class InspectionVerdict:
    """The inspection's answer on one onion.

    Attributes
    ----------
    prediction : int
        The value the inspector was given for "bad" if ``p_blemished`` reaches the threshold,
        for "good" below it, for "unknown" if no view showed an onion (by default the sorting
        task's ``prediction`` values 1, 0 and 2).
    p_blemished : float or None
        The fused probability that the onion is blemished (None: no view showed one).
    view_p_blemished : tuple of (float or None)
        Each view's own probability (None where the detector found no onion).
    threshold : float
        The probability at which the onion is called blemished.
    """

    prediction: int
    p_blemished: float | None
    view_p_blemished: tuple[float | None, ...] = field(default=())
    threshold: float = 0.5


class InspectionClassifier:
    """The trained network with its calibrations.

    The network is trained to see rot: its logit says whether the view shows a blemish. Two
    calibrations of that one logit give the probabilities the fusion rules need
    (:mod:`perception.fusion`):

    - :meth:`rot_probabilities`, ``sigmoid(z / temperature)``: that the view shows rot (a
      temperature fitted on validation views labelled by the rot they show);
    - :meth:`probabilities`, ``sigmoid(a z + b)``: that the onion in the view is blemished, rot
      in sight or not (Platt's two parameters fitted on the same views labelled by the onion's
      class, its classes weighted to ``train_prior``).

    Attributes
    ----------
    net : InspectionNet
    temperature : float
    platt : (float, float)
        ``(a, b)``.
    train_prior : float
        The share of blemished onions :meth:`probabilities` are calibrated to.
    rot_prior : float
        The share of views showing rot :meth:`rot_probabilities` are calibrated to.
    visibility : float
        The chance that a view of a blemished onion shows its rot (measured on the training
        views; the ``noisy-or`` rule's).
    rule : {"noisy-or", "log-odds"}
        The fusion rule chosen for this model (on validation onions).
    fused_calibration : dict
        Per fusion rule, the map ``(low, high, form[, low_power, high_power])`` that
        calibrates the fused probability
        (:func:`perception.fusion.fuse`'s ``calibration``; fitted on held-out onions by
        :func:`onionsort.stages.inspection.fit_fused_calibration`); a rule not in it is fused
        as it stands.
    device : torch.device
    """

    def __init__(self, net: InspectionNet, temperature: float = 1.0,
                 platt: tuple[float, float] = (1.0, 0.0), train_prior: float = 0.5, *,
                 rot_prior: float = 0.5, visibility: float = 0.8, rule: str = "noisy-or",
                 metadata: dict | None = None, device: str | torch.device = "cpu",
                 fused_calibration: dict | None = None) -> None:
        if not temperature > 0:
            raise ValueError(f"temperature must be > 0; got {temperature}")
        if not 0.0 < train_prior < 1.0:
            raise ValueError(f"train_prior must be in (0, 1); got {train_prior}")
        if rule not in FUSION_RULES:
            raise ValueError(f"rule must be one of {FUSION_RULES}; got {rule!r}")
        self.device = torch.device(device)
        self.net = net.to(self.device).eval()
        self.temperature = float(temperature)
        self.platt = (float(platt[0]), float(platt[1]))
        if not 0.0 < rot_prior < 1.0:
            raise ValueError(f"rot_prior must be in (0, 1); got {rot_prior}")
        if not 0.0 < visibility <= 1.0:
            raise ValueError(f"visibility must be in (0, 1]; got {visibility}")
        self.train_prior = float(train_prior)
        self.rot_prior = float(rot_prior)
        self.visibility = float(visibility)
        self.rule = rule
        self.metadata = dict(metadata or {})
        self.fused_calibration: dict[str, tuple] = {}
        for key, value in (fused_calibration or {}).items():
            self.set_fused_calibration(key, value)

    def set_fused_calibration(self, rule: str, calibration) -> None:
        """Calibrate the fused probability of ``rule`` by ``calibration`` ``(low, high[,
        form[, low_power, high_power]])`` (:func:`perception.fusion.check_calibration`; None:
        fuse as it stands)."""
        if rule not in FUSION_RULES:
            raise ValueError(f"rule must be one of {FUSION_RULES}; got {rule!r}")
        checked = check_calibration(calibration)
        if checked is None:
            self.fused_calibration.pop(rule, None)
        else:
            self.fused_calibration[rule] = checked

    @classmethod
    def load(cls, path: Path | str, device: str | torch.device = "cpu") -> InspectionClassifier:
        """Load a checkpoint written by :meth:`save`."""

        def build(ckpt: dict) -> InspectionClassifier:
            if ckpt.get("kind") != "inspection-classifier":
                raise ValueError(f"its kind is {ckpt.get('kind')!r}")
            net = InspectionNet(InspectionNetConfig(**ckpt["config"]))
            net.load_state_dict(ckpt["model"])
            return cls(net, ckpt["temperature"], tuple(ckpt["platt"]), ckpt["train_prior"],
                       rot_prior=ckpt["rot_prior"], visibility=ckpt["visibility"],
                       rule=ckpt["rule"], metadata=ckpt.get("metadata", {}), device=device)

        return load_checkpoint(path, "inspection classifier checkpoint", build)

    def save(self, path: Path | str) -> Path:
        """Write the weights, configuration and calibration (atomically)."""
        return save_checkpoint(path, kind="inspection-classifier",
                               config=asdict(self.net.config), model=self.net,
                               temperature=self.temperature, platt=list(self.platt),
                               train_prior=self.train_prior, rot_prior=self.rot_prior,
                               visibility=self.visibility, rule=self.rule,
                               metadata=self.metadata)

    @torch.no_grad()
    def logits(self, crops: Sequence[np.ndarray], batch_size: int = 256) -> np.ndarray:
        """Raw logits (N,) of crops (S, S, 3) uint8 (:func:`crop_onion`)."""
        out = []
        for i in range(0, len(crops), batch_size):
            x = to_tensor(crops[i:i + batch_size]).to(self.device)
            out.append(self.net(x).float().cpu().numpy())
        return np.concatenate(out) if out else np.zeros(0)

    def calibrated(self, logits: np.ndarray, rule: str) -> np.ndarray:
        """The per-view probabilities ``rule`` fuses, from the network's ``logits`` (N,):
        that the view shows rot (temperature scaling) for ``noisy-or``, that the onion is
        blemished (Platt scaling) for ``log-odds``."""
        if rule not in FUSION_RULES:
            raise ValueError(f"rule must be one of {FUSION_RULES}; got {rule!r}")
        z = np.asarray(logits, float)
        if rule == "noisy-or":
            return 1.0 / (1.0 + np.exp(-z / self.temperature))
        a, b = self.platt
        return 1.0 / (1.0 + np.exp(-(a * z + b)))

    def rot_probabilities(self, crops: Sequence[np.ndarray]) -> np.ndarray:
        """Calibrated probabilities (N,) that each crop shows rot."""
        return self.calibrated(self.logits(crops), "noisy-or")

    def probabilities(self, crops: Sequence[np.ndarray]) -> np.ndarray:
        """Calibrated probabilities (N,) that each crop's onion is blemished."""
        return self.calibrated(self.logits(crops), "log-odds")

    def view_probabilities(self, crops: Sequence[np.ndarray], rule: str) -> np.ndarray:
        """The per-view probabilities ``rule`` fuses (:meth:`calibrated`) of crops."""
        return self.calibrated(self.logits(crops), rule)

    def fuse(self, view_p: Sequence[float], rule: str, prior: float = 0.5) -> float:
        """:func:`perception.fusion.fuse` of views this classifier read, with its
        calibration: under ``rule``, for a line whose share of blemished onions is
        ``prior``."""
        return fuse(view_p, rule, prior=prior, train_prior=self._train_prior(rule),
                    visibility=self.visibility, calibration=self.fused_calibration.get(rule))

    def settled(self, view_p: Sequence[float], remaining: int, rule: str, *,
                threshold: float, prior: float = 0.5) -> bool:
        """:func:`perception.fusion.settled` for views this classifier read: whether the
        call at ``threshold`` stays the same whatever ``remaining`` more views show."""
        return settled(view_p, remaining, rule, threshold=threshold, prior=prior,
                       train_prior=self._train_prior(rule), visibility=self.visibility,
                       calibration=self.fused_calibration.get(rule))

    def _train_prior(self, rule: str) -> float:
        """The share the per-view probabilities of ``rule`` are calibrated to."""
        return self.rot_prior if rule == "noisy-or" else self.train_prior


class Inspector:
    """The robot's and the sorter's inspection: the detector finds the onion in each view, the
    classifier reads it, the views are fused and the onion called at the cost threshold.

    It is what :class:`robot.station.SawyerStation` takes as ``classify`` (a call on an onion's
    views gives an :class:`InspectionVerdict`), and what the sorter's prediction factor reads
    (:meth:`view_probabilities` and :meth:`fuse`).

    Parameters
    ----------
    detector : perception.Detector
    classifier : InspectionClassifier
    rule : {"noisy-or", "log-odds"} or None
        How views are fused (:func:`perception.fusion.fuse`); None: the classifier's own.
    threshold : float in (0, 1)
        The fused probability from which an onion is called blemished
        (:func:`perception.fusion.cost_threshold`).
    prior : float in (0, 1)
        The line's share of blemished onions (log-odds fusion).
    values : (int, int, int)
        What a verdict answers for good, bad and unknown (the sorting task's ``prediction``
        values by default).
    """

    def __init__(self, detector, classifier: InspectionClassifier, *, rule: str | None = None,
                 threshold: float = 0.5, prior: float = 0.5,
                 values: tuple[int, int, int] = (0, 1, 2)) -> None:
        rule = classifier.rule if rule is None else rule
        if rule not in FUSION_RULES:
            raise ValueError(f"rule must be one of {FUSION_RULES}; got {rule!r}")
        if not 0.0 < threshold < 1.0:
            raise ValueError(f"threshold must be in (0, 1); got {threshold!r}")
        if not 0.0 < prior < 1.0:
            raise ValueError(f"prior must be in (0, 1); got {prior!r}")
        self.detector, self.classifier = detector, classifier
        self.rule, self.threshold, self.prior = rule, float(threshold), float(prior)
        self.values = tuple(int(v) for v in values)
        self._recent: dict[str, object] = {}  # view digest -> its detections

    def boxes(self, views: Sequence[np.ndarray]) -> list[np.ndarray | None]:
        """The onion's box (4,) in each view: the detector's best box of either class at or
        above :data:`INSPECTION_SCORE`; None where it found none. The detections of the last
        views are kept (:meth:`last_detections`)."""
        found = self.detector.detect(list(views)) if len(views) else []
        for view, det in zip(views, found, strict=True):
            self._recent[_digest([view])] = det
        while len(self._recent) > _RECENT:
            del self._recent[next(iter(self._recent))]
        return [best_box(det) for det in found]

    def last_detections(self, views: Sequence[np.ndarray]) -> list | None:
        """The detector's detections of ``views`` if it read them among the last views
        inspected (one at a time or together), else None."""
        found = self._known(views)
        return None if any(det is None for det in found) else found

    def detections(self, views: Sequence[np.ndarray]) -> list:
        """The detector's detections of each of ``views``: those it read among the last views
        inspected as they were, the others detected now. What a log or a perception topic
        draws, without running the detector on a view twice."""
        found = self._known(views)
        missing = [i for i, det in enumerate(found) if det is None]
        if missing:
            for i, det in zip(missing, self.detector.detect([views[i] for i in missing]),
                              strict=True):
                found[i] = det
        return found

    def _known(self, views: Sequence[np.ndarray]) -> list:
        """The kept detections of each view (None where it was not read lately)."""
        return [self._recent.get(_digest([v])) for v in views]

    def view_probabilities(self, views: Sequence[np.ndarray]) -> list[float | None]:
        """Each view's calibrated probability, as the fusion rule reads it (that the view
        shows rot for ``noisy-or``, that its onion is blemished for ``log-odds``); None where
        the detector found no onion."""
        boxes = self.boxes(views)
        crops = [crop_onion(v, b) for v, b in zip(views, boxes, strict=True) if b is not None]
        probs = (iter(self.classifier.view_probabilities(crops, self.rule).tolist()) if crops
                 else iter(()))
        return [None if b is None else next(probs) for b in boxes]

    def fuse(self, view_p: Sequence[float]) -> float:
        """One probability from the probabilities of views of one onion."""
        return self.classifier.fuse(view_p, self.rule, self.prior)

    def settled(self, view_p: Sequence[float | None], remaining: int) -> bool:
        """Whether the call on an onion whose views so far gave ``view_p`` (None where the
        detector found no onion) stays the same whatever ``remaining`` more views give
        (:func:`perception.fusion.settled`): the robot can stop showing it."""
        seen = [p for p in view_p if p is not None]
        if not seen:  # the call is "unknown" until a view shows the onion
            return remaining == 0
        return self.classifier.settled(seen, remaining, self.rule, threshold=self.threshold,
                                       prior=self.prior)

    def verdict(self, view_p: Sequence[float | None]) -> InspectionVerdict:
        """The verdict on one onion from its views' probabilities (:meth:`view_probabilities`;
        None where the detector found no onion)."""
        per_view = tuple(None if p is None else float(p) for p in view_p)
        seen = [p for p in per_view if p is not None]
        good, bad, unknown = self.values
        if not seen:
            return InspectionVerdict(unknown, None, per_view, self.threshold)
        p_bad = self.fuse(seen)
        return InspectionVerdict(bad if p_bad >= self.threshold else good, p_bad, per_view,
                                 self.threshold)

    def __call__(self, views: Sequence[np.ndarray]) -> InspectionVerdict:
        """The verdict on one onion from its views (each (H, W, 3) uint8)."""
        return self.verdict(self.view_probabilities(views))


def best_box(detections) -> np.ndarray | None:
    """The onion's box (4,) among one view's ``detections`` (:class:`perception.Detections`):
    the best of either class if it scores :data:`INSPECTION_SCORE` or more, else None."""
    scores = np.asarray(detections.scores)
    if scores.size == 0 or scores.max() < INSPECTION_SCORE:
        return None
    return np.asarray(detections.boxes)[int(scores.argmax())]


_RECENT = 4096
"""Views whose detections an :class:`Inspector` keeps for :meth:`Inspector.last_detections`
(a session's inspection views, read in one call, are a few hundred)."""


def _digest(views: Sequence[np.ndarray]) -> str:
    h = hashlib.blake2b(digest_size=16)
    for v in views:
        v = np.ascontiguousarray(v)
        h.update(repr((v.shape, v.dtype.str)).encode())
        h.update(v.data)
    return h.hexdigest()
