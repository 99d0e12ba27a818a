"""Several seeds of a motor memory (Rec-SMA) trained at once: the stacked LSTM of
``stacked_lstm`` under an open-loop head run by autograd.

Rec-SMA trains on 4 streams of 256 steps (``engine._open_loop_epoch``), so a seed alone keeps
a core busy with tiny products: every time step of the LSTM and every step of the open loop
is a handful of calls on a few hundred numbers, for forward and backward alike. Stacked, K
seeds share each call. The memory (``sensor_in``, the LSTM reading [h_t, m_{t-1}],
``sensor_out``) runs through ``stacked_lstm``'s kernels, forward and backward by hand; the
head, ``models.SensorimotorEncoder.ahead`` on stacked weights (``baddbmm`` per layer), runs
under autograd from the beliefs z_s, whose gradient then goes back through the memory by
hand. Shapes are time-major, (K, T, B, .):

    memory   x_t = [relu(W_in s_t + b_in), m_{t-1}]    h_t = LSTM(x_t)    z_t = W_out h_t + b
    head     z^0 = z_t (every ``every``-th t)    for k = 0 .. A - 1:
                 p_k = predictor([z^k, z_m(m_{t+k})])  ~ s_{t+k+1}
                 z^{k+1} = z^k + transition([z^k, z_m(m_{t+k})])
    loss     per seed, sum over (k, t, b) of w (p_k - s_{t+k+1})^2 summed over the 5 sensors,
             over the sum of w (``engine._open_loop_epoch``'s loss, each seed its own)

A seed's numbers agree with its ``nn.Module`` trained alone (``engine.AutogradEngine``) to
float32 rounding; ``check.computes_models_py`` compares the loss and every gradient with
autograd through ``models.py`` before the engine uses this.
"""

from __future__ import annotations

import torch

from sensorimotor.learn.batches import stream_layout
from sensorimotor.learn.fast.private import relu_grad_
from sensorimotor.learn.fast.products import linear, matmul, weight_grad
from sensorimotor.learn.fast.stacked import StackedEncoders
from sensorimotor.learn.fast.stacked_lstm import (
    State,
    carried,
    chunk_buffers,
    lstm_backward,
    lstm_forward,
)

HEAD = ("motor_encoder", "predictor", "transition")  # the chains autograd runs

OpenLoopState = tuple[State, torch.Tensor | None]  # the LSTM's, and the last command (B, 2)


def _chain(net: StackedEncoders, leaves: dict[int, torch.Tensor], chain: str, h):
    """One chain of ``nn.Linear`` layers on stacked weights, under autograd: h (K, N, in) ->
    (K, N, out), a ReLU after all but the last."""
    layers = net.chains[chain]
    for i in layers:
        w, b = (leaves[j] for j in net.linear_index[i])
        h = torch.baddbmm(b, h, w.mT)  # (K, N, out)
        if i != layers[-1]:
            h = h.relu()
    return h


def forward_backward(
    net: StackedEncoders,
    xs: torch.Tensor,
    xm: torch.Tensor,
    y: torch.Tensor,
    weight: torch.Tensor,
    state: OpenLoopState | None,
    ahead: int,
    every: int,
) -> tuple[OpenLoopState, torch.Tensor, torch.Tensor]:
    """One chunk of every seed: the loss gradient into ``net.grads``; returns the state after
    the chunk, each seed's weighted squared error summed (K,) and the weights' sum.

    xs (T, B, 5) the chunk's readings s_t; xm (T + A - 1, B, 2) the commands m_t from the
    chunk's first step on; y (T + A - 1, B, 5) the readings s_{t+1} alike; weight (A, T', B),
    T' = ceil(T / every): 1 where the k-th prediction from step t counts (its target inside
    the split). All shared by the seeds."""
    c = net.config
    K, plan, grads = net.k, net.layers, net.grads
    T, B, _ = xs.shape
    n = T * B
    bufs = chunk_buffers(net, T, B)
    lstm_state, last = (None, None) if state is None else state

    # the memory: [relu(sensor_in(s_t)), m_{t-1}] (K, TB, 18) -> LSTM -> z_s (K, TB, 10)
    x_in = xs.reshape(1, n, -1).expand(K, n, -1)
    (i_in,) = net.chains["sensor_in"]
    x = linear(x_in, *plan[i_in]).relu_()  # (K, TB, 16)
    first = xm.new_zeros(1, B, xm.shape[-1]) if last is None else last[None]  # m_{-1}
    before = torch.cat([first, xm[: T - 1]])  # m_{t-1}: (T, B, 2)
    if not c.reads_motors:
        before = torch.zeros_like(before)  # the ablation: the memory reads no command
    memory_in = torch.cat([x, before.reshape(1, n, -1).expand(K, n, -1)], dim=-1)
    inputs = lstm_forward(net, bufs, memory_in, lstm_state)
    (i_out,) = net.chains["sensor_out"]
    z = linear(inputs[-1], *plan[i_out])  # (K, TB, 10)

    # the head under autograd, from the beliefs z_s
    leaves = {j: net.params[j].detach().requires_grad_() for ch in HEAD
              for i in net.chains[ch] for j in net.linear_index[i]}  # fmt: skip
    z_leaf = z.view(K, T, B, -1).detach().requires_grad_()  # (K, T, B, 10)
    with torch.enable_grad():
        z_m = _chain(net, leaves, "motor_encoder", xm.reshape(1, -1, 2).expand(K, -1, -1))
        z_m = z_m.view(K, len(xm), B, -1)  # (K, T + A - 1, B, 5)
        belief = z_leaf[:, ::every]  # (K, T', B, 10)
        t_ = belief.shape[1]
        zz = []  # the predictor's input of every k: the belief and the command's code
        for k in range(ahead):
            zz.append(torch.cat([belief, z_m[:, k : k + T : every]], dim=-1))  # (K, T', B, 15)
            if k + 1 < ahead:
                flat = zz[-1].reshape(K, t_ * B, -1)
                belief = belief + _chain(net, leaves, "transition", flat).view(K, t_, B, -1)
        # every k's prediction in one pass: (K, A T' B, 15) -> (K, A, T', B, 5) ~ s_{t+k+1}
        pred = _chain(net, leaves, "predictor", torch.stack(zz, 1).view(K, ahead * t_ * B, -1))
        target = torch.stack([y[k : k + T : every] for k in range(ahead)])  # (A, T', B, 5)
        err = (pred.view(K, ahead, t_, B, -1) - target).square().sum(-1) * weight  # (K, A, T', B)
        count = weight.sum()
        per_seed = err.sum((1, 2, 3))  # (K,)
        (per_seed / count.clamp(min=1)).sum().backward()
    for j, leaf in leaves.items():
        if leaf.grad is None:  # the transition when A = 1: no gradient, as under autograd
            grads[j].zero_()
        else:
            grads[j].copy_(leaf.grad)
    dz = z_leaf.grad.reshape(K, n, -1)  # (K, TB, 10)

    # back through the memory by hand
    wi, bi = net.linear_index[i_out]
    weight_grad(dz, inputs[-1], grads[wi])
    torch.sum(dz, 1, keepdim=True, out=grads[bi])
    dh = lstm_backward(net, bufs, inputs, matmul(dz, plan[i_out][0]))  # (K, TB, 18)
    dpre = relu_grad_(dh[..., : x.shape[-1]].contiguous(), x)  # through sensor_in's ReLU
    wi, bi = net.linear_index[i_in]
    weight_grad(dpre, x_in, grads[wi])
    torch.sum(dpre, 1, keepdim=True, out=grads[bi])
    return (carried(bufs), xm[T - 1].clone()), per_seed.detach(), count


def train_epoch_stacked_open_loop(
    net: StackedEncoders,
    s: torch.Tensor,
    m: torch.Tensor,
    streams: int,
    horizon: int,
    ahead: int,
    every: int,
) -> torch.Tensor:
    """One epoch of every seed of a motor memory, as ``engine._open_loop_epoch`` runs it for
    one (the same streams, chunks, targets and weights); each seed's mean error (K,) over
    every (step, k) inside the split."""
    n = len(s) - 1
    index, mask = stream_layout(n, streams)
    length = index.shape[1]
    grid = index[:, :1] + torch.arange(length + ahead - 1)  # (B, L + A - 1): the data go on
    inside = torch.stack([grid[:, :length] + k + 1 <= n for k in range(ahead)])
    inside &= mask  # (A, B, L)
    w = inside.float().transpose(1, 2).contiguous().to(s.device)  # (A, L, B), time-major
    at = grid.clamp(max=n).T.contiguous().to(s.device)  # (L + A - 1, B)
    xs, xm, y = s[at], m[at], s[(at + 1).clamp(max=n)]  # (L + A - 1, B, 5|2|5)
    total = torch.zeros(net.k, device=s.device)
    count = torch.zeros((), device=s.device)
    state = None
    with torch.no_grad():
        for j in range(0, length, horizon):
            t = min(horizon, length - j)
            state, sq, c = forward_backward(
                net, xs[j : j + t], xm[j : j + t + ahead - 1], y[j : j + t + ahead - 1],
                w[:, j : j + t : every], state, ahead, every,
            )  # fmt: skip
            net.adam_step()
            total += sq
            count += c
    return total / count
