"""What the training loop drives, and its one door to ``fast``: an engine trains several seeds
of one model through one epoch at a time.

The loop (``train.train_runs``) owns the run folders, early stopping, checkpoints and records;
an engine owns only the arithmetic, behind four calls:

    train_epoch(epoch) -> each seed's mean training error
    val_errors()       -> each seed's validation error (and each seed's model brought up to date)
    snapshot(k)        -> seed k's model and Adam state, to save
    keep(index)        -> only those seeds go on (the others stopped)

and ``merge(engines)``, which joins engines whose seeds reached the same epoch (a resume
after a kill between two seeds' checkpoints). ``AutogradEngine`` trains each seed's
``nn.Module`` with autograd through ``models.py``; ``StackedEngine`` trains them all as one
network with stacked weights (``fast.stacked``, ``fast.stacked_lstm``,
``fast.stacked_open_loop``), to float32 rounding the same numbers, wherever
``computes_models_py`` says the stacked passes compute what ``models.py`` computes.

Nothing outside this module imports ``fast``: the loop, the pipeline and the command line
reach its optimiser (``FusedAdam``), its check (``computes_models_py``) and its process
settings (``flush_subnormals``, ``keep_freed_memory``) from here.

Feed-forward models (S, SM) see the train split's transitions (s_t, m_t) -> s_{t+1} shuffled,
every one once per epoch. Recurrent models see the train split cut into ``batch_size``
contiguous streams; each batch is the next ``horizon`` steps of every stream, the LSTM state
carried (detached) from one batch to the next and reset at each epoch (truncated
back-propagation through time). The data live as tensors and are gathered once per epoch so
that each batch is a view; nothing in the step loop talks to the host.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import torch

from sensorimotor.learn.batches import epoch_generator, stream_layout
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.evaluate import ahead_errors, model_error
from sensorimotor.learn.fast import cuda_graphs
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.check import computes_models_py
from sensorimotor.learn.fast.cpu import flush_subnormals, keep_freed_memory
from sensorimotor.learn.fast.stacked import StackedEncoders, train_epoch_stacked
from sensorimotor.learn.fast.stacked_lstm import sequence_errors, train_epoch_stacked_recurrent
from sensorimotor.learn.fast.stacked_open_loop import train_epoch_stacked_open_loop
from sensorimotor.learn.models import SensorimotorEncoder
from sensorimotor.learn.slowness import slowness_prior

__all__ = [  # the engines, and what the loop, the pipeline and the command line take of fast
    "AutogradEngine",
    "Engine",
    "FusedAdam",
    "Member",
    "StackedEngine",
    "TrainData",
    "computes_models_py",
    "flush_subnormals",
    "keep_freed_memory",
    "train_epoch_feedforward",
    "train_epoch_recurrent",
]


@dataclass
class Member:
    """One seed in an engine: its model and optimiser, and which database it trains on."""

    seed: int
    split: int  # index of its database in TrainData
    model: SensorimotorEncoder  # the seed's weights (kept up to date by val_errors)
    opt: FusedAdam  # its Adam state when the engine is built


@dataclass
class TrainData:
    """The scaled train splits, resident on the training device, and the validation splits.

    ``s`` (n + 1, 5) and ``m`` (n + 1, 2) for one database, or (W, n + 1, 5|2) for W
    databases of one train length; ``val`` one (sensors, motors) pair per database."""

    s: torch.Tensor
    m: torch.Tensor
    val: list[tuple[torch.Tensor, torch.Tensor]]

    def train_split(self, split: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Database ``split``'s (sensors, motors) train tensors."""
        return (self.s[split], self.m[split]) if self.s.dim() == 3 else (self.s, self.m)


class Engine(Protocol):
    members: list[Member]

    def train_epoch(self, epoch: int) -> list[float]: ...

    def val_errors(self) -> list[float]: ...

    def snapshot(self, k: int) -> tuple[SensorimotorEncoder, dict]: ...

    def keep(self, index: Sequence[int]) -> None: ...


def member_errors(members: Sequence[Member], data: TrainData, config: TrainConfig) -> list[float]:
    """Each seed's validation error through its ``nn.Module``; with ``ahead`` > 1 the
    open-loop errors' mean, what it was trained on."""
    if config.ahead > 1:
        return [
            float(ahead_errors(mb.model, *data.val[mb.split], config.ahead).mean())
            for mb in members
        ]
    return [model_error(mb.model, *data.val[mb.split]) for mb in members]


class AutogradEngine:
    """Each seed's ``nn.Module`` trained with autograd and ``FusedAdam``, one after another:
    the reference the stacked engine is checked against, and what trains a model that the
    stacked passes do not compute, or the recurrent models on CUDA (cuDNN)."""

    def __init__(self, members: Sequence[Member], data: TrainData, config: TrainConfig):
        self.members, self.data, self.config = list(members), data, config

    @classmethod
    def merge(cls, engines: Sequence[AutogradEngine]) -> AutogradEngine:
        return cls([mb for e in engines for mb in e.members], engines[0].data, engines[0].config)

    def train_epoch(self, epoch: int) -> list[float]:
        c, errors = self.config, []
        for mb in self.members:
            s, m = self.data.train_split(mb.split)
            mb.model.train()
            if mb.model.config.recurrent:
                error = train_epoch_recurrent(
                    mb.model, mb.opt, s, m, c.batch_size, c.horizon, c.ahead, c.ahead_every,
                    slow_dims=c.slow_dims, slow_weight=c.slow_weight,
                )  # fmt: skip
            else:
                order = epoch_generator(mb.seed, epoch)
                error = train_epoch_feedforward(mb.model, mb.opt, s, m, c.batch_size, order)
            errors.append(error)
        return errors

    def val_errors(self) -> list[float]:
        return member_errors(self.members, self.data, self.config)

    def snapshot(self, k: int) -> tuple[SensorimotorEncoder, dict]:
        return self.members[k].model, self.members[k].opt.state_dict()

    def keep(self, index: Sequence[int]) -> None:
        self.members = [self.members[i] for i in index]


class StackedEngine:
    """Every seed of one model as one network with a leading seed axis: one
    ``fast.stacked.StackedEncoders``, trained by ``fast.stacked`` (feed-forward) or
    ``fast.stacked_lstm`` (recurrent; its kernels are CPU code) or ``fast.stacked_open_loop``
    (a motor memory, on the same kernels). Every seed's ``nn.Module`` is
    brought up to date after each epoch, for validation and saving."""

    def __init__(
        self,
        members: Sequence[Member],
        data: TrainData,
        config: TrainConfig,
        net: StackedEncoders | None = None,
    ):
        self.members, self.data, self.config = list(members), data, config
        if net is None:
            models, opts = [mb.model for mb in members], [mb.opt for mb in members]
            net = StackedEncoders.from_models(models, opts, lr=config.lr)
        self.net = net
        self.recurrent = self.net.config.recurrent
        if self.recurrent and data.s.dim() == 3:
            raise ValueError("a recurrent stack trains on one database")

    @classmethod
    def merge(cls, engines: Sequence[StackedEngine]) -> StackedEngine:
        net = StackedEncoders.concat([e.net for e in engines])
        members = [mb for e in engines for mb in e.members]
        return cls(members, engines[0].data, engines[0].config, net)

    def train_epoch(self, epoch: int) -> list[float]:
        c = self.config
        if self.net.config.motor_memory:
            errors = train_epoch_stacked_open_loop(
                self.net, self.data.s, self.data.m, c.batch_size, c.horizon, c.ahead,
                c.ahead_every, slow_dims=c.slow_dims, slow_weight=c.slow_weight,
            )  # fmt: skip
        elif self.recurrent:
            errors = train_epoch_stacked_recurrent(
                self.net, self.data.s, self.data.m, c.batch_size, c.horizon
            )
        else:
            seeds = [mb.seed for mb in self.members]  # each seed's own data order
            splits = [mb.split for mb in self.members]
            s, m = self.data.s, self.data.m
            errors = train_epoch_stacked(self.net, s, m, seeds, epoch, c.batch_size, splits)
        return errors.tolist()

    def val_errors(self) -> list[float]:
        for k, mb in enumerate(self.members):
            self.net.load_into(k, mb.model)
        if self.net.config.motor_memory:  # each seed's model, as AutogradEngine scores it
            return member_errors(self.members, self.data, self.config)
        if self.recurrent:  # every seed at once, as evaluate.model_error does each
            return sequence_errors(self.net, *self.data.val[0])
        return [model_error(mb.model, *self.data.val[mb.split]) for mb in self.members]

    def snapshot(self, k: int) -> tuple[SensorimotorEncoder, dict]:
        return self.members[k].model, self.net.optimizer_state(k)

    def keep(self, index: Sequence[int]) -> None:
        if 0 < len(index) < len(self.members):  # an empty engine is dropped, not shrunk
            self.net.select(index)
        self.members = [self.members[i] for i in index]


def train_epoch_feedforward(model, opt, s, m, batch: int, gen: torch.Generator) -> float:
    """One epoch over shuffled transitions; returns the mean training error."""
    n = len(s) - 1
    perm = torch.randperm(n, generator=gen).to(s.device)
    xs, xm, y = s[:-1][perm], m[:-1][perm], s[1:][perm]  # (n, 5), (n, 2), (n, 5) gathered once
    total = torch.zeros((), device=s.device)
    for i in range(0, n, batch):
        pred, _, _ = model(xs[i : i + batch], xm[i : i + batch])  # (b, 5)
        loss = ((pred - y[i : i + batch]) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += loss.detach() * len(pred)
    return float(total) / n


def train_epoch_recurrent(
    model,
    opt,
    s,
    m,
    streams: int,
    horizon: int,
    ahead: int = 1,
    every: int = 1,
    slow_dims: int = 0,
    slow_weight: float = 1.0,
) -> float:
    """One epoch of truncated BPTT over ``streams`` contiguous streams; mean training error.

    A model with a motor memory predicts s_{t+1} .. s_{t+ahead} open loop from every
    ``every``-th step (``models.SensorimotorEncoder.ahead``): the loss is their mean, each
    target inside the split (a stream's last steps look into the data that follow it), plus
    ``slow_weight`` times the slowness prior on z_s's first ``slow_dims`` dimensions (the
    returned error is the prediction's alone). On CUDA the chunks that
    no stream's end pads run as one replayed graph each (``fast.cuda_graphs``): the same
    arithmetic, a fraction of the launches."""
    n = len(s) - 1
    index, mask = stream_layout(n, streams)
    graphed = 0  # leading steps of every stream run by the graph
    if cuda_graphs.enabled(s) and not model.config.motor_memory:
        unmasked = int(mask.all(0).long().cumprod(0).sum())  # columns before the first pad
        graphed = unmasked // horizon * horizon
    if model.config.motor_memory:
        return _open_loop_epoch(
            model, opt, s, m, index, mask, horizon, ahead, every, slow_dims, slow_weight
        )
    w = None if bool(mask.all()) else mask.float().to(s.device)  # (streams, L)
    index = index.to(s.device)
    xs, xm, y = s[:-1][index], m[:-1][index], s[1:][index]  # (streams, L, 5|2|5)
    total = torch.zeros((), device=s.device)
    state = None
    if graphed:
        step = cuda_graphs.recurrent_step(model, opt, streams, horizon)
        step.h.zero_()
        step.c.zero_()
        total = step.total.zero_()
        for j in range(0, graphed, horizon):
            for buf, src in ((step.x, xs), (step.xm, xm), (step.y, y)):
                buf.copy_(src[:, j : j + horizon])
            cuda_graphs.replay_recurrent(step, model, opt)
        state = (step.h.clone(), step.c.clone())
    for j in range(graphed, index.shape[1], horizon):
        pred, _, state = model(xs[:, j : j + horizon], xm[:, j : j + horizon], state)
        state = tuple(t.detach() for t in state)  # carry, but stop gradients (truncation)
        err = ((pred - y[:, j : j + horizon]) ** 2).sum(-1)  # (streams, h)
        if w is None:
            loss = err.mean()
            total += loss.detach() * err.numel()
        else:
            wj = w[:, j : j + horizon]
            loss = (err * wj).sum() / wj.sum()
            total += (err * wj).sum().detach()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return float(total) / n


def _open_loop_epoch(
    model,
    opt,
    s,
    m,
    index,
    mask,
    horizon: int,
    ahead: int,
    every: int,
    slow_dims: int,
    slow_weight: float,
) -> float:
    """``train_epoch_recurrent`` for a motor memory: each chunk's beliefs z_s predict the
    ``ahead`` readings after every step (and, with ``slow_dims``, change slowly: the prior
    reads every step of the chunk, the one padded step at a short stream's end included);
    returns the prediction's mean error over every (step, k) inside the split."""
    n = len(s) - 1
    length = index.shape[1]
    grid = index[:, :1] + torch.arange(length + ahead - 1)  # (B, L + K - 1): the data go on
    inside = torch.stack([grid[:, :length] + k + 1 <= n for k in range(ahead)])
    inside &= mask  # (K, B, L): a start of the stream, its target inside the split
    w = inside.float().to(s.device)
    at = grid.clamp(max=n).to(s.device)
    xs, xm, y = s[at], m[at], s[(at + 1).clamp(max=n)]  # (B, L + K - 1, 5|2|5)
    total = torch.zeros((), device=s.device)
    count = torch.zeros((), device=s.device)
    state = None
    for j in range(0, index.shape[1], horizon):
        t = min(horizon, index.shape[1] - j)
        z, state = model.encode(xs[:, j : j + t], state, xm[:, j : j + t])  # (B, t, 10)
        state = tuple(h.detach() for h in state)  # carry, but stop gradients (truncation)
        pred = model.ahead(z, xm[:, j : j + t + ahead - 1], ahead, every)  # (K, B, t', 5)
        target = torch.stack([y[:, j + k : j + k + t : every] for k in range(ahead)])
        wj = w[:, :, j : j + t : every]  # (K, B, t')
        err = ((pred - target) ** 2).sum(-1) * wj
        loss = err.sum() / wj.sum().clamp(min=1)
        if slow_dims:
            loss = loss + slow_weight * slowness_prior(z, slow_dims)
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += err.sum().detach()
        count += wj.sum()
    return float(total / count)
