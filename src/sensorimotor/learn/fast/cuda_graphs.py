"""Training steps replayed as CUDA graphs, for the data resident on a GPU.

On a GPU these tiny models are bound by kernel launches, not arithmetic: an eager Rec-SM step
of 64 streams x 20 steps launches a few hundred kernels, and launching them takes longer than
running them (``docs/benchmarks.md`` has the measurements). A CUDA graph records a
step's kernels once, reading its inputs from fixed buffers; each replay runs the same kernels
on the buffers' new contents in one launch. Only the launching changes, so the numbers are the eager loop's (tests check
it); ``engine.train_epoch_recurrent`` and ``stacked.train_epoch_stacked`` use this on CUDA.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

ENABLED = True  # False: the eager loops on CUDA too (tests compare the two)


def enabled(data: torch.Tensor) -> bool:
    """Whether training on ``data``'s device replays graphs: on CUDA, unless switched off."""
    return ENABLED and data.is_cuda


def capture(step: Callable[[], None]) -> torch.cuda.CUDAGraph:
    """Run ``step`` once for real on a side stream (the warm-up a capture needs), then record
    it as a graph. The caller counts the warm-up as a step; each replay is one more."""
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        step()
    torch.cuda.current_stream().wait_stream(side)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        step()
    return graph


@dataclass
class RecurrentStep:
    """One truncated-BPTT step of ``engine.train_epoch_recurrent`` as a graph: inputs x, xm, y
    (streams, horizon, 5|2|5), the LSTM state (h, c) carried in place from step to step, and
    the epoch's summed squared error ``total``."""

    x: torch.Tensor
    xm: torch.Tensor
    y: torch.Tensor
    h: torch.Tensor
    c: torch.Tensor
    total: torch.Tensor
    graph: torch.cuda.CUDAGraph | None = None


def recurrent_step(model, opt, streams: int, horizon: int) -> RecurrentStep:
    """The graph of ``model``'s step with ``opt`` (an ``adam.FusedAdam``), made once per shape
    and kept on the optimizer; captured by the first ``replay_recurrent`` call."""
    key = ("recurrent", streams, horizon)
    if key not in opt.graphs:
        c = model.config
        dev = next(model.parameters()).device
        state = torch.zeros(c.lstm_layers, streams, c.lstm_size, device=dev)
        opt.graphs[key] = RecurrentStep(
            torch.zeros(streams, horizon, c.n_sensors, device=dev),
            torch.zeros(streams, horizon, c.n_motors, device=dev),
            torch.zeros(streams, horizon, c.n_sensors, device=dev),
            state,
            state.clone(),
            torch.zeros((), device=dev),
        )
    return opt.graphs[key]


def replay_recurrent(step: RecurrentStep, model, opt) -> None:
    """One step on what ``step``'s buffers hold: the eager loop's arithmetic, in its order."""
    if step.graph is not None:
        step.graph.replay()
        return

    def eager() -> None:
        pred, _, (h, c) = model(step.x, step.xm, (step.h, step.c))
        err = ((pred - step.y) ** 2).sum(-1)  # (streams, horizon)
        loss = err.mean()
        step.total.add_(loss.detach() * err.numel())
        opt.zero_grad()  # the graph's gradients: allocated in its pool, rewritten each replay
        loss.backward()
        opt.step()
        step.h.copy_(h.detach())
        step.c.copy_(c.detach())

    step.graph = capture(eager)


GRAPH_BATCHES = 32  # feed-forward batches a graph runs: K x 2,048 transitions


@dataclass
class StackedSteps:
    """``GRAPH_BATCHES`` steps of a ``stacked.StackedEncoders`` as a graph: each seed's inputs
    x, xm, y (K, GRAPH_BATCHES x batch, 5|2|5), and the epoch's squared errors sq_sum (K, 1, 1)."""

    x: torch.Tensor
    xm: torch.Tensor | None
    y: torch.Tensor
    sq_sum: torch.Tensor
    batch: int
    graph: torch.cuda.CUDAGraph | None = None


def stacked_steps(net, batch: int) -> StackedSteps:
    """The graph of ``net``'s steps at ``batch``, made once and kept on the stack (until its
    seeds change); captured by the first ``replay_stacked`` call."""
    if batch not in net.graphs:
        c, k, rows = net.config, net.k, GRAPH_BATCHES * batch
        dev = net.params[0].device
        xm = torch.zeros(k, rows, c.n_motors, device=dev) if c.uses_motors else None
        net.graphs[batch] = StackedSteps(
            torch.zeros(k, rows, c.n_sensors, device=dev),
            xm,
            torch.zeros(k, rows, c.n_sensors, device=dev),
            torch.zeros(k, 1, 1, device=dev),
            batch,
        )
    return net.graphs[batch]


def replay_stacked(steps: StackedSteps, net) -> None:
    """``GRAPH_BATCHES`` steps of every seed on what ``steps``' buffers hold, in order."""
    if steps.graph is not None:
        steps.graph.replay()
        return

    def eager() -> None:
        for i in range(0, steps.x.shape[1], steps.batch):
            b = slice(i, i + steps.batch)
            xm = None if steps.xm is None else steps.xm[:, b]
            net.forward_backward(steps.x[:, b], xm, steps.y[:, b], steps.sq_sum)
            net.adam_step()

    steps.graph = capture(eager)
