"""The one training loop (:mod:`perception.trainer`) and checkpoint files
(:mod:`perception.checkpoint`)."""

import copy
import math

import pytest
import torch
from torch import nn

from perception.checkpoint import load_checkpoint, save_checkpoint
from perception.trainer import ema


def _net() -> nn.Module:
    torch.manual_seed(0)
    return nn.Sequential(nn.Linear(3, 4), nn.BatchNorm1d(4), nn.Linear(4, 1))


def test_the_moving_average_ramps_its_decay_and_averages_buffers_exactly():
    """Step k moves every float tensor (weights and batch norm's statistics) to
    d e + (1 - d) p with d = decay (1 - exp(-k / warmup)), bit for bit, and copies counts."""
    net = _net()
    average, by_hand = ema(net, 0.9, warmup=3.0), copy.deepcopy(net)
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    for step in range(1, 6):
        net(torch.randn(8, 3)).pow(2).mean().backward()
        opt.step()
        average.update_parameters(net)
        d = 0.9 * (1 - math.exp(-step / 3.0))
        for e, p in zip(by_hand.state_dict().values(), net.state_dict().values(), strict=True):
            if e.dtype.is_floating_point:
                e.mul_(d).add_(p, alpha=1 - d)
            else:
                e.copy_(p)
    for name, value in by_hand.state_dict().items():
        assert torch.equal(average.module.state_dict()[name], value), name
    assert average.module.state_dict()["1.num_batches_tracked"] == 5


def test_checkpoints_are_written_whole_and_read_with_clear_errors(tmp_path):
    net = _net()
    path = save_checkpoint(tmp_path / "model.pt", config={"width": 4}, model=net)
    assert [p.name for p in tmp_path.iterdir()] == ["model.pt"]  # no .partial left
    doc = load_checkpoint(path, "test checkpoint")
    assert doc["config"] == {"width": 4}
    assert all(torch.equal(doc["model"][k], v) for k, v in net.state_dict().items())
    with pytest.raises(FileNotFoundError, match="no test checkpoint at"):
        load_checkpoint(tmp_path / "missing.pt", "test checkpoint")
    with pytest.raises(ValueError, match=r"is not an other checkpoint \('nothing'\)"):
        load_checkpoint(path, "other checkpoint", lambda d: d["nothing"])
