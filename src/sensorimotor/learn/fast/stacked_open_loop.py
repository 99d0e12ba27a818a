"""Several seeds of a motor memory (Rec-SMA) trained at once: the stacked LSTM of
``stacked_lstm`` under an open-loop head, forward and backward by hand.

Rec-SMA trains on 4 streams of 256 steps (``engine._open_loop_epoch``), so a seed alone keeps
a core busy with tiny products: every time step of the LSTM and every step of the open loop
is a handful of calls on a few hundred numbers, for forward and backward alike. Stacked, K
seeds share each call. The memory (``sensor_in``, the LSTM reading [h_t, m_{t-1}],
``sensor_out``) runs through ``stacked_lstm``'s kernels; the head,
``models.SensorimotorEncoder.ahead`` on stacked weights, through ``StackedEncoders``'s layer
passes (``_forward``, ``_backward``), one k at a time (``_head``); the gradient of the
beliefs z_s then goes back through the memory. Shapes are time-major, (K, T, B, .):

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
from sensorimotor.learn.slowness import prior_gradient

OpenLoopState = tuple[State, torch.Tensor | None]  # the LSTM's, and the last command (B, 2)


def _head(
    net: StackedEncoders,
    z: torch.Tensor,
    xm: torch.Tensor,
    y: torch.Tensor,
    weight: torch.Tensor,
    ahead: int,
    every: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The open-loop head of every seed, forward and backward by hand from the beliefs z
    (K, T, B, 10): its chains' gradients into ``net.grads``; returns d loss / d z (K, T, B, 10)
    and each seed's weighted squared error summed (K,). xm, y and weight as ``forward_backward``'s.

    One k at a time, so that the predictor's hidden layer (K, T'B, 128) stays in the cache
    (all k at once, under autograd, it went through memory at twice the cost): the predictor's
    gradient goes to its input at once, then the transitions' run back from k = A - 1 to 0."""
    plan, grads = net.layers, net.grads
    K, T, B, zs = z.shape
    for chain in ("predictor", "transition"):  # applied at every k: their gradients add up
        for i in net.chains[chain]:
            for j in net.linear_index[i]:
                grads[j].zero_()
    hm = net._forward(plan, "motor_encoder", xm.reshape(1, -1, xm.shape[-1]).expand(K, -1, -1))
    z_m = hm[-1].view(K, len(xm), B, -1)  # (K, T + A - 1, B, 5): m_t's code at [:, t]
    belief = z[:, ::every]  # (K, T', B, 10)
    t_ = belief.shape[1]
    rows = t_ * B
    belief = belief.reshape(K, rows, zs)
    scale = 2.0 / weight.sum().clamp(min=1)  # d/dpred of the loss is scale w (pred - s)
    per_seed = z.new_zeros(K)
    dzz, trans = [], []  # d loss / d [belief, z_m] through the predictor; the transitions' inputs
    for k in range(ahead):
        zz = torch.cat([belief, z_m[:, k : k + T : every].reshape(K, rows, -1)], dim=-1)
        hp = net._forward(plan, "predictor", zz)  # [(K, T'B, 15), (K, T'B, 128), (K, T'B, 5)]
        diff = hp[-1] - y[k : k + T : every].reshape(1, rows, -1)  # ~ s_{t+k+1}
        wd = diff * weight[k].reshape(1, rows, 1)
        per_seed += (wd * diff).sum((1, 2))
        dzz.append(
            net._backward(plan, grads, "predictor", hp, wd.mul_(scale), input_grad=True, add=True)
        )
        if k + 1 < ahead:
            trans.append(net._forward(plan, "transition", zz))  # [zz, (K, T'B, 64), (K, T'B, 10)]
            belief = belief + trans[-1][-1]  # the belief after m_{t+k}
    dzm = torch.zeros_like(z_m)  # (K, T + A - 1, B, 5)
    g = None  # d loss / d belief_{k+1}
    for k in range(ahead - 1, -1, -1):
        d = dzz[k]  # (K, T'B, 15)
        if g is not None:  # belief_{k+1} = belief_k + transition(zz_k)
            d = d + net._backward(plan, grads, "transition", trans[k], g, input_grad=True, add=True)
            d[..., :zs] += g
        g = d[..., :zs]
        dzm[:, k : k + T : every] += d[..., zs:].reshape(K, t_, B, -1)
    net._backward(plan, grads, "motor_encoder", hm, dzm.view(K, -1, dzm.shape[-1]))
    dz = torch.zeros_like(z)
    dz[:, ::every] = g.reshape(K, t_, B, zs)
    return dz, per_seed


def forward_backward(
    net: StackedEncoders,
    xs: torch.Tensor,
    xm: torch.Tensor,
    y: torch.Tensor,
    weight: torch.Tensor,
    state: OpenLoopState | None,
    ahead: int,
    every: int,
    slow_dims: int = 0,
    slow_weight: float = 1.0,
) -> tuple[OpenLoopState, torch.Tensor, torch.Tensor]:
    """One chunk of every seed: the loss gradient into ``net.grads``; returns the state after
    the chunk, each seed's weighted squared error summed (K,) and the weights' sum.

    xs (T, B, 5) the chunk's readings s_t; xm (T + A - 1, B, 2) the commands m_t from the
    chunk's first step on; y (T + A - 1, B, 5) the readings s_{t+1} alike; weight (A, T', B),
    T' = ceil(T / every): 1 where the k-th prediction from step t counts (its target inside
    the split). All shared by the seeds. With ``slow_dims``, each seed's loss also holds
    ``slow_weight`` times the slowness prior of its z_s over the chunk
    (``learn.slowness``; its gradient by autograd, a few small operations)."""
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

    # the head, forward and backward by hand from the beliefs z_s
    dz, per_seed = _head(net, z.view(K, T, B, -1), xm, y, weight, ahead, every)
    if slow_dims:  # the prior reads each stream's window: (K, B, T, 10)
        beliefs = z.view(K, T, B, -1).transpose(1, 2)
        dz += prior_gradient(beliefs, slow_dims, slow_weight).transpose(1, 2)
    dz = dz.view(K, n, -1)  # (K, TB, 10)

    # back through the memory by hand
    wi, bi = net.linear_index[i_out]
    weight_grad(dz, inputs[-1], grads[wi])
    torch.sum(dz, 1, keepdim=True, out=grads[bi])
    dh = lstm_backward(net, bufs, inputs, matmul(dz, plan[i_out][0]))  # (K, TB, 18)
    dpre = relu_grad_(dh[..., : x.shape[-1]].contiguous(), x)  # through sensor_in's ReLU
    wi, bi = net.linear_index[i_in]
    weight_grad(dpre, x_in, grads[wi])
    torch.sum(dpre, 1, keepdim=True, out=grads[bi])
    return (carried(bufs), xm[T - 1].clone()), per_seed, weight.sum()


def train_epoch_stacked_open_loop(
    net: StackedEncoders,
    s: torch.Tensor,
    m: torch.Tensor,
    streams: int,
    horizon: int,
    ahead: int,
    every: int,
    slow_dims: int = 0,
    slow_weight: float = 1.0,
) -> torch.Tensor:
    """One epoch of every seed of a motor memory, as ``engine._open_loop_epoch`` runs it for
    one (the same streams, chunks, targets, weights and prior); each seed's mean prediction
    error (K,) over every (step, k) inside the split."""
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
                w[:, j : j + t : every], state, ahead, every, slow_dims, slow_weight,
            )  # fmt: skip
            net.adam_step()
            total += sq
            count += c
    return total / count
