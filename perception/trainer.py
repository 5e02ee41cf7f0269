"""One training loop for every model here: the detector, the inspection classifier and the
state classifier all train through :func:`fit`.

A model brings what is its own: its network, optimiser and learning-rate schedule, its training
batches (drawn, and augmented where the augmentation moves the labels too), its loss, and its
validation (a score, higher better, and the figures to log). The loop does the rest, once for
all: mixed precision on CUDA, gradient clipping, an exponential moving average of the weights
(:func:`ema`), the augmentation of training inputs (``augment``, never on validation), the
history and its log, progress (``on_epoch``), keeping the best epoch (``on_best``), early stopping
(``patience``), and a checkpoint of the run that :func:`fit` resumes from exactly (``last``).

Layouts: a batch is ``(x, target, weight)``: the network's inputs ``x[n, ...]``, whatever the
model's loss reads as its target, and the batch's weight in the epoch's mean training loss.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.optim.swa_utils import AveragedModel

from perception.checkpoint import save_checkpoint

__all__ = ["Fit", "ema", "fit"]

logger = logging.getLogger(__name__)


def ema(net: nn.Module, decay: float, warmup: float = 200.0) -> AveragedModel:
    """An exponential moving average of ``net``'s weights and buffers (torch's
    :class:`~torch.optim.swa_utils.AveragedModel`), starting at its weights now.

    Update ``k`` (from 1) moves each floating-point tensor ``e`` to ``d e + (1 - d) p`` with
    ``d = decay (1 - exp(-k / warmup))``, a short memory while the weights move fast early on,
    and copies the others (batch norm's counts). The average is ``.module``.
    """

    @torch.no_grad()
    def update(averaged: list[torch.Tensor], current: list[torch.Tensor], n: torch.Tensor
               ) -> None:
        if not averaged[0].is_floating_point():
            for a, c in zip(averaged, current, strict=True):
                a.copy_(c)
            return
        d = decay * (1 - math.exp(-int(n) / warmup))
        torch._foreach_mul_(averaged, d)
        torch._foreach_add_(averaged, current, alpha=1 - d)

    averaged = AveragedModel(net, multi_avg_fn=update, use_buffers=True)
    averaged.update_parameters(net)  # the first update copies
    return averaged.eval()


@dataclass(frozen=True)
class Fit:
    """What :func:`fit` did: ``history`` (one record per epoch: ``epoch``, ``train_loss`` and
    the validation's figures), the ``best`` score and the epoch it came from."""

    history: list[dict]
    best: float
    best_epoch: int


def _float(out: Any) -> Any:
    """A network's outputs (a tensor, a tuple or a dict of them) in float32."""
    if isinstance(out, torch.Tensor):
        return out.float()
    if isinstance(out, dict):
        return {k: v.float() for k, v in out.items()}
    return type(out)(v.float() for v in out)


def fit(net: nn.Module, optimizer: torch.optim.Optimizer,
        scheduler: torch.optim.lr_scheduler.LRScheduler,
        batches: Callable[[int], Iterable[tuple[torch.Tensor, Any, float]]],
        loss: Callable[[Any, Any], torch.Tensor],
        validate: Callable[[nn.Module], tuple[float, dict]], *, epochs: int,
        on_best: Callable[[nn.Module], object], device: str | torch.device = "cpu",
        augment: Callable[[torch.Tensor], torch.Tensor] | None = None,
        clip_grad: float | None = None, average: AveragedModel | None = None,
        patience: int | None = None, on_epoch: Callable[[dict], None] | None = None,
        last: Path | str | None = None, meta: dict | None = None,
        rng: np.random.Generator | None = None, resume: dict | None = None,
        name: str = "model") -> Fit:
    """Train ``net`` for ``epochs``, validating after each; keep the best.

    Parameters
    ----------
    net : nn.Module
        On ``device``; on CUDA the forward pass runs in float16 autocast with a gradient
        scaler, on the CPU in float32.
    optimizer, scheduler
        The scheduler steps once per batch.
    batches : callable
        ``batches(epoch)``: the epoch's training batches ``(x, target, weight)``.
    loss : callable
        ``loss(outputs, target)``: the scalar to minimise, of the network's outputs in float32.
    validate : callable
        ``validate(model)``: ``(score, figures)`` of the model validated (``net``, or the
        average with ``average``); the higher the score the better.
    epochs : int
    on_best : callable
        Called with the model validated whenever its score beats the best so far: keep it.
    augment : callable, optional
        ``augment(x)``: the training inputs as the network sees them (drawing its randomness
        from torch's generator, or its own); never called on validation.
    clip_grad : float, optional
        Clip the gradient's norm to this.
    average : AveragedModel, optional
        A moving average of the weights (:func:`ema`), updated after every step; it is what
        is validated and kept.
    patience : int, optional
        Stop once this many epochs in a row have not beaten the best score.
    on_epoch : callable, optional
        Called with each epoch's history record, e.g. to draw a progress bar.
    last : path, optional
        Where to write the run after every epoch (network, average, optimiser, scheduler,
        history, best, torch's generator and ``rng``'s state, and ``meta``): what ``resume``
        continues from.
    meta : dict, optional
        More entries of ``last`` (e.g. the configuration, for the caller to check on resume).
    rng : numpy.random.Generator, optional
        The generator ``batches`` draws from, restored on ``resume``.
    resume : dict, optional
        A checkpoint ``last`` wrote: continue that run exactly.
    name : str
        The model's name in the log.
    """
    if patience is not None and patience < 1:
        raise ValueError(f"patience must be >= 1; got {patience}")
    device = torch.device(device)
    amp = device.type == "cuda"
    scaler = torch.amp.GradScaler("cuda", enabled=amp)
    watched = net if average is None else average.module
    start, history, best, best_epoch = 0, [], -math.inf, -1
    if resume is not None:
        net.load_state_dict(resume["model"])
        optimizer.load_state_dict(resume["optimizer"])
        scheduler.load_state_dict(resume["scheduler"])
        if average is not None:
            average.module.load_state_dict(resume["ema"])
            # the first update copied, then one per step
            average.n_averaged.fill_(scheduler.last_epoch + 1)
        torch.set_rng_state(resume["torch_rng"])
        if rng is not None:
            rng.bit_generator.state = resume["numpy_rng"]
        start, history, best = resume["epoch"] + 1, resume["history"], resume["best"]
        best_epoch = resume.get("best_epoch", resume["epoch"])
        logger.info("%s: resuming from epoch %d of %d", name, start, epochs)
    for epoch in range(start, epochs):
        if patience is not None and epoch - best_epoch > patience:
            logger.info("%s: no better score for %d epochs; stopping after epoch %d", name,
                        patience, epoch - 1)
            break
        net.train()
        total = seen = 0.0
        for x, target, weight in batches(epoch):
            if augment is not None:
                x = augment(x)
            with torch.autocast(device_type=device.type, dtype=torch.float16, enabled=amp):
                out = net(x.to(device))
            value = loss(_float(out), target)
            optimizer.zero_grad()
            scaler.scale(value).backward()
            if clip_grad is not None:
                scaler.unscale_(optimizer)
                nn.utils.clip_grad_norm_(net.parameters(), clip_grad)
            scaler.step(optimizer)
            scaler.update()
            scheduler.step()
            if average is not None:
                average.update_parameters(net)
            total += value.item() * weight
            seen += weight
        score, figures = validate(watched)
        history.append({"epoch": epoch, "train_loss": total / seen if seen else 0.0,
                        **figures})
        logger.info("%s epoch %d: %s", name, epoch, history[-1])
        if on_epoch is not None:
            on_epoch(history[-1])
        if score > best:
            best, best_epoch = score, epoch
            on_best(watched)
        if last is not None:
            save_checkpoint(last, model=net,
                            **({} if average is None else {"ema": average.module}),
                            optimizer=optimizer.state_dict(), scheduler=scheduler.state_dict(),
                            epoch=epoch, history=history, best=best, best_epoch=best_epoch,
                            torch_rng=torch.get_rng_state(),
                            **({} if rng is None else {"numpy_rng": rng.bit_generator.state}),
                            **(meta or {}))
    return Fit(history, best, best_epoch)
