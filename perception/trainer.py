"""One training loop, :func:`fit`, for the detector, the inspection and the state classifiers.

A model brings its network, optimiser, schedule, batches, loss and validation; the loop does the
rest once for all: mixed precision on CUDA, gradient clipping, a moving average of the weights
(:func:`ema`), augmentation, the history and its log, keeping the best epoch (early stopping),
and a checkpoint of the run to resume from exactly. A batch is ``(x, target, weight)``: inputs
``x[n, ...]``, what the loss reads, and the batch's weight in the epoch's mean loss.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.optim.swa_utils import AveragedModel

from perception.checkpoint import save_checkpoint

__all__ = ["ema", "fit"]

logger = logging.getLogger(__name__)


def ema(net: nn.Module, decay: float, warmup: float = 200.0) -> AveragedModel:
    """A moving average of ``net``'s weights and buffers, starting at them (``.module``).

    Update ``k`` (from 1) moves each floating-point tensor ``e`` to ``d e + (1 - d) p``, with
    ``d = decay (1 - exp(-k / warmup))`` (a short memory early on), and copies the others.
    """

    @torch.no_grad()
    def update(averaged: list, current: list, n: torch.Tensor) -> None:
        if not averaged[0].is_floating_point():
            torch._foreach_copy_(averaged, current)
            return
        d = decay * (1 - math.exp(-int(n) / warmup))
        torch._foreach_mul_(averaged, d)
        torch._foreach_add_(averaged, current, alpha=1 - d)

    averaged = AveragedModel(net, multi_avg_fn=update, use_buffers=True)
    averaged.update_parameters(net)  # the first update copies
    return averaged.eval()


def _float(out: Any) -> Any:
    """A network's outputs (a tensor, or a tuple or dict of them) in float32."""
    if isinstance(out, dict):
        return {k: v.float() for k, v in out.items()}
    return out.float() if isinstance(out, torch.Tensor) else type(out)(v.float() for v in out)


def fit(net: nn.Module, optimizer: torch.optim.Optimizer,
        scheduler: torch.optim.lr_scheduler.LRScheduler,
        batches: Callable[[int], Iterable[tuple[torch.Tensor, Any, float]]],
        loss: Callable[[Any, Any], torch.Tensor],
        validate: Callable[[nn.Module], tuple[float, dict]], *, epochs: int,
        on_best: Callable[[nn.Module], object], device: str | torch.device = "cpu",
        augment: Callable[[torch.Tensor], torch.Tensor] | None = None,
        clip_grad: float | None = None, average: AveragedModel | None = None,
        on_epoch: Callable[[dict], None] | None = None,
        last: Path | str | None = None, meta: dict | None = None,
        rng: np.random.Generator | None = None, resume: dict | None = None,
        name: str = "model") -> list[dict]:
    """Train ``net`` (on ``device``) for ``epochs``; return the history, a record per epoch.

    Parameters
    ----------
    batches, loss, validate : callable
        ``batches(epoch)`` gives the epoch's training batches; ``loss(outputs, target)`` the
        scalar to minimise (outputs in float32); ``validate(model)`` ``(score, figures)``, the
        higher the score the better, of ``net`` (or of ``average.module``).
    on_best : callable
        Called with the validated model whenever its score beats the best so far.
    augment : callable, optional
        ``augment(x)``: training inputs as the network sees them; never on validation.
    clip_grad : float, optional
        The largest norm of the gradient.
    average : AveragedModel, optional
        :func:`ema` of ``net``, updated after each step; validated and kept in its place.
    on_epoch : callable, optional
        Called with each epoch's record (``epoch``, ``train_loss``, the figures).
    last, meta, rng, resume
        After each epoch, write the run to ``last`` (weights, optimiser, scheduler, history,
        torch's and ``rng``'s states, and ``meta``); ``resume``, a checkpoint so written,
        continues that run.
    """
    device = torch.device(device)
    amp = device.type == "cuda"  # float16 autocast and a gradient scaler; float32 on the CPU
    scaler = torch.amp.GradScaler("cuda", enabled=amp)
    watched = net if average is None else average.module
    start, history, best = 0, [], -math.inf
    if resume is not None:
        net.load_state_dict(resume["model"])
        optimizer.load_state_dict(resume["optimizer"])
        scheduler.load_state_dict(resume["scheduler"])
        if average is not None:
            average.module.load_state_dict(resume["ema"])
            average.n_averaged.fill_(scheduler.last_epoch + 1)  # a copy, then one per step
        torch.set_rng_state(resume["torch_rng"])
        if rng is not None:
            rng.bit_generator.state = resume["numpy_rng"]
        start, history, best = resume["epoch"] + 1, resume["history"], resume["best"]
        logger.info("%s: resuming from epoch %d of %d", name, start, epochs)
    for epoch in range(start, epochs):
        net.train()
        total = seen = 0.0
        for x, target, weight in batches(epoch):
            x = x if augment is None else augment(x)
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
            total, seen = total + value.item() * weight, seen + weight
        score, figures = validate(watched)
        history.append({"epoch": epoch, "train_loss": total / seen if seen else 0.0, **figures})
        logger.info("%s epoch %d: %s", name, epoch, history[-1])
        if on_epoch is not None:
            on_epoch(history[-1])
        if score > best:
            best = score
            on_best(watched)
        if last is not None:
            save_checkpoint(last, model=net, **({} if average is None else {"ema": watched}),
                            optimizer=optimizer.state_dict(), scheduler=scheduler.state_dict(),
                            epoch=epoch, history=history, best=best,
                            torch_rng=torch.get_rng_state(),
                            **({} if rng is None else {"numpy_rng": rng.bit_generator.state}),
                            **(meta or {}))
    return history
