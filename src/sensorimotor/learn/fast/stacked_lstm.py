"""Several seeds of a recurrent encoder (Rec-S, Rec-SM) trained at once, the LSTM by hand.

PyTorch's CPU LSTM spends most of a truncated-BPTT step (64 streams x 20 steps, 3 x 32
units) on per-element work: its backward pass runs at a third of the speed of its forward.
Here K seeds run as tensors with a leading seed axis; all of them see the same batches (the
recurrent protocol does not shuffle), every product goes to the BLAS (``bmm``, ``baddbmm``), and
the per-element work of one time step, gates, cell and their derivatives, runs for every seed
in one numba kernel, which also adds the bias and the step's recurrent product and sums the
bias gradient. Shapes are time-major, (K, T, B, .), H = 32 units:

    forward   a_t = b + x_t W_ih^T + h_{t-1} W_hh^T           (K, B, 4H): gates i, f, g, o
              i, f, o = sigma(.)   g = tanh(.)   c_t = f c_{t-1} + i g   h_t = o tanh(c_t)
    backward  dh_t += da_{t+1} W_hh        dc += dh_t o (1 - tanh(c_t)^2)
              da_t = [dc g i(1-i), dc c_{t-1} f(1-f), dc i (1-g^2), dh_t tanh(c_t) o(1-o)]
              dc <- dc f      db += da_t   dW_ih = da^T x    dW_hh = da^T h_{t-1}    dx = da W_ih

numba has no vector ``exp``, so tanh is a rational function x P(x^2) / Q(x^2) fitted for this
file (max error 3e-7 in float32, a few units in the last place) and sigma(x) = (1 + tanh(x/2))
/ 2. A seed's numbers therefore agree with ``nn.LSTM`` to float32 rounding, not bit for bit;
tests check gradients against autograd through ``models.SensorimotorEncoder``, and that a
seed trains the same in a stack of K as alone (bit for bit, with one thread, as training runs).
The trained weights are the model's own (``nn.LSTM``'s layout, gate order i, f, g, o):
evaluation and analysis run ``models.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import torch

from sensorimotor.learn.batches import stream_layout
from sensorimotor.learn.fast.private import relu_grad_
from sensorimotor.learn.fast.products import ALIGN_ROWS, linear, matmul, weight_grad
from sensorimotor.learn.fast.stacked import StackedEncoders

# tanh(x) ~ x P(x^2) / Q(x^2) on |x| <= TANH_CLAMP (beyond it float32 tanh is +-1); relative
# minimax fit by iterated weighted least squares against float64 tanh.
TANH_CLAMP = np.float32(7.905311107635498)
P0, P1, P2, P3, P4, P5, P6 = (np.float32(c) for c in (
    0.9999999995928991, 0.13135372061943626, 0.003161826823380048, 1.1778680104245297e-05,
    -2.2918834628224284e-08, 6.69754066696719e-11, -1.2570312331139817e-13,
))  # fmt: skip
Q1, Q2, Q3 = (
    np.float32(c) for c in (0.4646870456187213, 0.02472419237118064, 0.0002631431913681189)
)
ONE, HALF = np.float32(1.0), np.float32(0.5)
# Fast math that still honours NaN (it must propagate, as in nn.LSTM), and no division check
# (error_model), so that the loops vectorise.
_FAST = {"fastmath": {"arcp", "contract", "afn", "reassoc", "nsz"}, "error_model": "numpy"}


@numba.njit(inline="always", **_FAST)
def tanh32(x):
    x = TANH_CLAMP if x > TANH_CLAMP else x  # a NaN passes both
    x = -TANH_CLAMP if x < -TANH_CLAMP else x
    u = x * x
    p = (((((P6 * u + P5) * u + P4) * u + P3) * u + P2) * u + P1) * u + P0
    q = ((Q3 * u + Q2) * u + Q1) * u + ONE
    return x * p / q


@numba.njit(cache=True, **_FAST)
def tanh_array(x: np.ndarray) -> np.ndarray:
    """``tanh32`` of every element (for tests and for checking the fit)."""
    out = np.empty_like(x)
    flat, res = x.ravel(), out.ravel()
    for i in range(flat.size):
        res[i] = tanh32(flat[i])
    return out


@numba.njit(cache=True, **_FAST)
def cell_forward(act, rec, bias, scale, hs, cs, tc, t):
    """Step t of every seed: act[:, t] (K, B, 4H) holds x_t W_ih^T; with the recurrent part
    rec (K, B, 4H) = h_{t-1} W_hh^T and bias (K, 4H) it becomes the gates, in place. Writes
    c_t to cs[:, t + 1], tanh(c_t) to tc[:, t] and h_t to hs[:, t + 1].

    One branch-free loop for all four gates: with scale s = 1/2 (sigma) or 1 (tanh), the gate
    is (1 - s) + s tanh(s a), which is (1 + tanh(a/2)) / 2 or tanh(a)."""
    K, _, B, G = act.shape
    H = G // 4
    for k in range(K):
        bk = bias[k]
        for b in range(B):
            a, r = act[k, t, b], rec[k, b]
            for u in range(G):
                s = scale[u]
                a[u] = (ONE - s) + s * tanh32(s * (a[u] + r[u] + bk[u]))
            i, f, g, o = a[:H], a[H : 2 * H], a[2 * H : 3 * H], a[3 * H :]
            c_prev, c_new = cs[k, t, b], cs[k, t + 1, b]
            for u in range(H):
                c_new[u] = f[u] * c_prev[u] + i[u] * g[u]
            tanh_c, h_new = tc[k, t, b], hs[k, t + 1, b]
            for u in range(H):
                tanh_c[u] = tanh32(c_new[u])
            for u in range(H):
                h_new[u] = o[u] * tanh_c[u]


@numba.njit(cache=True, **_FAST)
def cell_backward(dh, rec, act, cs, tc, dc, da, db, t):
    """Step t backwards: from dh[:, t] (K, B, H) from above, rec (K, B, H) = da_{t+1} W_hh
    from the future, and dc (K, B, H) = dL/dc_t, write da[:, t] (K, B, 4H) = dL/d(gate
    pre-activations), add it to db (K, 4H) and turn dc into dL/dc_{t-1}."""
    K, _, B, G = act.shape
    H = G // 4
    for k in range(K):
        dbk = db[k]
        for b in range(B):
            a, d, dc_kb = act[k, t, b], da[k, t, b], dc[k, b]
            dh_t, r, th, c_prev = dh[k, t, b], rec[k, b], tc[k, t, b], cs[k, t, b]
            for u in range(H):
                i, f, g, o = a[u], a[H + u], a[2 * H + u], a[3 * H + u]
                dhu = dh_t[u] + r[u]
                dcu = dc_kb[u] + dhu * o * (ONE - th[u] * th[u])
                d[u] = dcu * g * i * (ONE - i)
                d[H + u] = dcu * c_prev[u] * f * (ONE - f)
                d[2 * H + u] = dcu * i * (ONE - g * g)
                d[3 * H + u] = dhu * th[u] * o * (ONE - o)
                dc_kb[u] = dcu * f
            for u in range(G):
                dbk[u] += d[u]


SMALL_STREAMS = 8  # at most this many streams, a step's recurrent product runs in numba


@numba.njit(cache=True, **_FAST)
def step_product(x, t, w, out):
    """out[k, b] = x[k, t, b] w[k] for every seed and stream: x (K, T, B, I), w (K, I, O),
    out (K, B, O). One time step's recurrent product at a few streams (Rec-SMA trains on 4),
    where a call of the BLAS costs more than its arithmetic; a seed's sums run in the same
    order whatever K."""
    K, _, B, n_in = x.shape
    n_out = w.shape[2]
    for k in range(K):
        wk = w[k]
        for b in range(B):
            xb, o = x[k, t, b], out[k, b]
            for u in range(n_out):
                o[u] = 0.0
            for j in range(n_in):
                xj, wj = xb[j], wk[j]
                for u in range(n_out):
                    o[u] += xj * wj[u]


@numba.njit(cache=True, **_FAST)
def layer_forward_small(act, w_t, bias, scale, hs, cs, tc, rec):
    """Every step of a chunk forward (``step_product``, then ``cell_forward``) in one call at a
    few streams, where the calls of two kernels a step cost more than their arithmetic:
    w_t (K, H, 4H) is W_hh^T, rec (K, B, 4H) scratch; the other arguments as ``cell_forward``'s."""
    for t in range(act.shape[1]):
        step_product(hs, t, w_t, rec)  # h_{t-1} = hs[:, t]
        cell_forward(act, rec, bias, scale, hs, cs, tc, t)


@numba.njit(cache=True, **_FAST)
def layer_backward_small(dh, rec, act, cs, tc, dc, da, db, w):
    """Every step of a chunk backward (``cell_backward``, then ``step_product`` with W_hh
    (K, 4H, H) into rec) in one call at a few streams, as ``layer_forward_small``."""
    for t in range(act.shape[1] - 1, -1, -1):
        cell_backward(dh, rec, act, cs, tc, dc, da, db, t)
        if t:
            step_product(da, t, w, rec)


@numba.njit(cache=True, **_FAST)
def layer_sequence(act, whh_t, bias, scale, h, c, hs):
    """One layer of every seed over a whole sequence of batch one, forward only: act (K, L,
    4H) holds x_t W_ih^T; h, c (K, H) the state, carried in place; writes h_t to hs (K, L, H).
    The product with W_hh, a (H) x (H, 4H) one per step, is too small for the BLAS."""
    K, L, G = act.shape
    H = G // 4
    a = np.empty(G, dtype=np.float32)
    for k in range(K):
        w, bk, hk, ck = whh_t[k], bias[k], h[k], c[k]
        for t in range(L):
            x = act[k, t]
            for u in range(G):
                a[u] = x[u] + bk[u]
            for j in range(0, H - 3, 4):  # four rows of W_hh^T a pass: fewer loads of a
                h0, h1, h2, h3 = hk[j], hk[j + 1], hk[j + 2], hk[j + 3]
                w0, w1, w2, w3 = w[j], w[j + 1], w[j + 2], w[j + 3]
                for u in range(G):
                    a[u] += (h0 * w0[u] + h1 * w1[u]) + (h2 * w2[u] + h3 * w3[u])
            for j in range(H - H % 4, H):
                hj, wj = hk[j], w[j]
                for u in range(G):
                    a[u] += hj * wj[u]
            for u in range(G):
                sc = scale[u]
                a[u] = (ONE - sc) + sc * tanh32(sc * a[u])
            out = hs[k, t]
            for u in range(H):
                cu = a[H + u] * ck[u] + a[u] * a[2 * H + u]
                ck[u] = cu
                hk[u] = a[3 * H + u] * tanh32(cu)
                out[u] = hk[u]


# --- a chunk of T steps through the whole encoder ------------------------------------------


@dataclass
class _LayerBuffers:
    """One LSTM layer's tensors for a chunk of T steps, reused from chunk to chunk."""

    act: torch.Tensor  # (K, T, B, 4H) x_t W_ih^T, then the gates
    hs: torch.Tensor  # (K, T + 1, B, H): h_{-1} (the carried state), h_0 .. h_{T-1}
    cs: torch.Tensor  # (K, T + 1, B, H): c alike
    tc: torch.Tensor  # (K, T, B, H): tanh(c_t)
    arrays: tuple  # numpy views of act, hs, cs, tc for the kernels
    h_steps: list[torch.Tensor]  # hs[:, t] for every t: views made once, not per step


@dataclass
class _Buffers:
    """Every tensor of a chunk but the gradients: each layer's, and scratch that the layers
    share (one step's recurrent product forwards and backwards, a layer's da and dc)."""

    layers: list[_LayerBuffers]
    rec: torch.Tensor  # (K, B, 4H): h_{t-1} W_hh^T
    rec_back: torch.Tensor  # (K, B, H): da_{t+1} W_hh
    da: torch.Tensor  # (K, T, B, 4H)
    da_steps: list[torch.Tensor]  # da[:, t] for every t
    dc: torch.Tensor  # (K, B, H)
    scale: np.ndarray  # (4H,): 1/2 for the sigmoid gates i, f, o; 1 for g


def gate_scale(h: int) -> np.ndarray:
    """(4H,) the kernels' gate scale: 1/2 for the sigmoid gates i, f, o; 1 for g (tanh)."""
    scale = np.full(4 * h, HALF, dtype=np.float32)
    scale[2 * h : 3 * h] = ONE
    return scale


def chunk_buffers(net: StackedEncoders, t: int, b: int) -> _Buffers:
    """The tensors of a chunk of ``t`` steps of ``b`` streams, made once and reused."""
    cache = net.__dict__.setdefault("_lstm_buffers", {})
    key = (net.k, t, b)
    if key not in cache:
        k, h = net.k, net.config.lstm_size
        layers = []
        for _ in range(net.config.lstm_layers):
            act = torch.empty(k, t, b, 4 * h)
            hs, cs = torch.empty(k, t + 1, b, h), torch.empty(k, t + 1, b, h)
            tc = torch.empty(k, t, b, h)
            arrays = tuple(x.numpy() for x in (act, hs, cs, tc))
            layers.append(_LayerBuffers(act, hs, cs, tc, arrays, list(hs.unbind(1))))
        cache.clear()  # at most two chunk lengths an epoch: keep only the current one
        da = torch.empty(k, t, b, 4 * h)
        cache[key] = _Buffers(
            layers,
            torch.empty(k, b, 4 * h),
            torch.empty(k, b, h),
            da,
            list(da.unbind(1)),
            torch.empty(k, b, h),
            gate_scale(h),
        )
    return cache[key]


def _lstm_params(net: StackedEncoders, layer: int) -> tuple[int, int, int, int]:
    """Indices in ``net.params`` of one layer's W_ih, W_hh, b_ih, b_hh."""
    return tuple(
        net.index[f"lstm.{p}_l{layer}"] for p in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
    )


State = list[tuple[torch.Tensor, torch.Tensor]] | None  # per layer (h, c), each (K, B, H)


def forward_backward(
    net: StackedEncoders,
    xs: torch.Tensor,
    xm: torch.Tensor | None,
    y: torch.Tensor,
    weight: torch.Tensor | None,
    state: State,
    sq_sum: torch.Tensor,
) -> State:
    """One chunk of every seed: the loss gradient into ``net.grads``, each seed's weighted
    squared error added to ``sq_sum`` (K,); returns the state after the chunk (detached).

    xs (T, B, 5) sensors, xm (T, B, 2) motors (None for Rec-S), y (T, B, 5) next sensors, all
    shared by the seeds; weight (T, B) 0/1 for padded stream ends, or None. The loss is the
    paper's error averaged over the chunk's (weighted) steps, as ``engine.train_epoch_recurrent``.
    """
    c = net.config
    K, plan, grads = net.k, net.layers, net.grads
    T, B, _ = xs.shape
    n = T * B
    bufs = chunk_buffers(net, T, B)

    # sensor_in: (K, TB, 5) -> relu -> (K, TB, 16)
    x_in = xs.reshape(1, n, -1).expand(K, n, -1)
    (i_in,) = net.chains["sensor_in"]
    x = linear(x_in, *plan[i_in]).relu_()  # (K, TB, 16)
    inputs = lstm_forward(net, bufs, x, state)
    (i_out,) = net.chains["sensor_out"]
    z = linear(inputs[-1], *plan[i_out])  # z_s (K, TB, 10)
    if c.uses_motors:
        hm = net._forward(plan, "motor_encoder", xm.reshape(1, n, -1).expand(K, n, -1))
        z = torch.cat([z, hm[-1]], dim=-1)  # (K, TB, 15)
    hp = net._forward(plan, "predictor", z)  # [(K, TB, 15), (K, TB, 128), pred (K, TB, 5)]
    diff = hp[-1].sub_(y.reshape(1, n, -1))  # (K, TB, 5)
    err = diff.square().sum(-1)  # (K, TB)
    if weight is None:
        sq_sum += err.sum(-1)
        dy = diff.mul_(2.0 / n)
    else:
        wv = weight.reshape(1, n)
        sq_sum += (err * wv).sum(-1)
        dy = diff.mul_((2.0 / wv.sum()) * wv[..., None])

    dz = net._backward(plan, grads, "predictor", hp, dy, input_grad=True)  # (K, TB, 10|15)
    if c.uses_motors:
        net._backward(plan, grads, "motor_encoder", hm, dz[..., c.z_sensors :])
        dz = dz[..., : c.z_sensors]
    wi, bi = net.linear_index[i_out]
    weight_grad(dz, inputs[-1], grads[wi])  # (K, 10, H)
    torch.sum(dz, 1, keepdim=True, out=grads[bi])
    dh = lstm_backward(net, bufs, inputs, matmul(dz, plan[i_out][0]))  # (K, TB, 16)
    dpre = relu_grad_(dh, inputs[0])  # through sensor_in's ReLU
    wi, bi = net.linear_index[i_in]
    weight_grad(dpre, x_in, grads[wi])
    torch.sum(dpre, 1, keepdim=True, out=grads[bi])
    return carried(bufs)


def lstm_forward(net: StackedEncoders, bufs: _Buffers, x: torch.Tensor, state: State):
    """Every LSTM layer over a chunk of T steps of B streams, from ``state`` (None: zero):
    x (K, TB, in), time-major -> [x, each layer's output (K, TB, H)], the inputs of the
    layers and the top's output (views of ``bufs``)."""
    K, T, B = bufs.da.shape[:3]
    n = T * B
    inputs = [x]  # input of every LSTM layer, (K, TB, in)
    rec, rec_a = bufs.rec, bufs.rec.numpy()
    for layer, buf in enumerate(bufs.layers):
        wih, whh, bih, bhh = (net.params[i] for i in _lstm_params(net, layer))
        torch.bmm(inputs[-1], wih.mT, out=buf.act.view(K, n, -1))  # x_t W_ih^T, every t
        bias = (bih + bhh).view(K, -1).numpy()  # (K, 4H)
        if state is None:
            buf.hs[:, 0].zero_()
            buf.cs[:, 0].zero_()
        else:
            buf.hs[:, 0].copy_(state[layer][0])
            buf.cs[:, 0].copy_(state[layer][1])
        act_a, hs_a, cs_a, tc_a = buf.arrays
        whh_t = whh.mT
        if B <= SMALL_STREAMS:
            w_t = whh_t.contiguous().numpy()  # (K, H, 4H)
            layer_forward_small(act_a, w_t, bias, bufs.scale, hs_a, cs_a, tc_a, rec_a)
        else:
            for t in range(T):
                torch.bmm(buf.h_steps[t], whh_t, out=rec)  # (K, B, 4H)
                cell_forward(act_a, rec_a, bias, bufs.scale, hs_a, cs_a, tc_a, t)
        inputs.append(buf.hs[:, 1:].reshape(K, n, -1))  # (K, TB, H), a view
    return inputs


def lstm_backward(
    net: StackedEncoders, bufs: _Buffers, inputs: list[torch.Tensor], dh: torch.Tensor
) -> torch.Tensor:
    """Back through every LSTM layer of ``lstm_forward``'s chunk (truncated at its start):
    dL/d(top output) dh (K, TB, H) -> every layer's gradients into ``net.grads``; returns
    dL/d(the first layer's input) (K, TB, in)."""
    K, T, B = bufs.da.shape[:3]
    n, grads = T * B, net.grads
    rec_back, da, dc = bufs.rec_back, bufs.da, bufs.dc
    rec_back_a, da_a, dc_a = rec_back.numpy(), da.numpy(), dc.numpy()
    da2 = da.view(K, n, -1)  # (K, TB, 4H)
    for layer in range(len(bufs.layers) - 1, -1, -1):
        buf = bufs.layers[layer]
        iwih, iwhh, ibih, ibhh = _lstm_params(net, layer)
        wih, whh = net.params[iwih], net.params[iwhh]
        dh4 = dh.reshape(K, T, B, -1)  # dL/dh_t from above; the kernel adds the future's
        db = grads[ibih].view(K, -1)  # (K, 4H)
        db.zero_()
        dc.zero_()
        rec_back.zero_()
        act_a, _, cs_a, tc_a = buf.arrays
        dh_a, db_a = dh4.numpy(), db.numpy()
        if B <= SMALL_STREAMS:
            w = whh.detach().numpy()  # (K, 4H, H)
            layer_backward_small(dh_a, rec_back_a, act_a, cs_a, tc_a, dc_a, da_a, db_a, w)
        else:
            for t in range(T - 1, -1, -1):
                cell_backward(dh_a, rec_back_a, act_a, cs_a, tc_a, dc_a, da_a, db_a, t)
                if t:
                    torch.bmm(bufs.da_steps[t], whh, out=rec_back)  # (K, B, H)
        weight_grad(da2, inputs[layer], grads[iwih])
        weight_grad(da2, buf.hs[:, :T].reshape(K, n, -1), grads[iwhh])
        grads[ibhh].copy_(grads[ibih])
        dh = torch.bmm(da2, wih)  # (K, TB, in): dL/d(layer input)
    return dh


def carried(bufs: _Buffers) -> State:
    """The state after the chunk, per layer (h, c) (K, B, H), copied out of the buffers."""
    return [(buf.hs[:, -1].clone(), buf.cs[:, -1].clone()) for buf in bufs.layers]


def train_epoch_stacked_recurrent(
    net: StackedEncoders, s: torch.Tensor, m: torch.Tensor, streams: int, horizon: int
) -> torch.Tensor:
    """One epoch of truncated BPTT for every seed of ``net``, as ``engine.train_epoch_recurrent``
    runs it for one: ``streams`` contiguous streams, chunks of ``horizon`` steps, the state
    carried (detached) and reset each epoch. Returns each seed's mean training error (K,)."""
    n = len(s) - 1
    index, mask = stream_layout(n, streams)
    index = index.T.contiguous().to(s.device)  # (L, streams), time-major
    xs, y = s[:-1][index], s[1:][index]  # (L, streams, 5)
    xm = m[:-1][index] if net.config.uses_motors else None  # (L, streams, 2)
    w = None if bool(mask.all()) else mask.T.float().to(s.device)  # (L, streams)
    sq_sum = torch.zeros(net.k, device=s.device)
    state = None
    with torch.no_grad():
        for j in range(0, index.shape[0], horizon):
            chunk = slice(j, j + horizon)
            state = forward_backward(
                net,
                xs[chunk],
                None if xm is None else xm[chunk],
                y[chunk],
                None if w is None else w[chunk],
                state,
                sq_sum,
            )
            net.adam_step()
    return sq_sum / n


def sequence_errors(
    net: StackedEncoders, sensors: torch.Tensor, motors: torch.Tensor, chunk: int = 4096
) -> list[float]:
    """Each seed's error over one contiguous split (n, 5), (n, 2), from a zero state carried
    throughout: ``evaluate.model_error`` of every seed at once, to float32 rounding.

    ``chunk`` steps run at a time, a multiple of 16 so that every seed's slab of a stacked
    product starts on a 64-byte boundary, as alone; the last chunk is padded at its end (the
    padding comes after every real step, and the state after it is not used)."""
    if chunk % ALIGN_ROWS:
        raise ValueError(f"chunk must be a multiple of {ALIGN_ROWS}, got {chunk}")
    c, plan, K = net.config, net.layers, net.k
    n, H = len(sensors), c.lstm_size
    scale = gate_scale(H)
    layers = []  # per LSTM layer: W_ih (K, 4H, in), W_hh^T (K, H, 4H), bias (K, 4H), h, c (K, H)
    for layer in range(c.lstm_layers):
        wih, whh, bih, bhh = (net.params[j] for j in _lstm_params(net, layer))
        whh_t = whh.mT.contiguous().numpy()
        bias = (bih + bhh).view(K, -1).numpy()
        layers.append(
            (wih, whh_t, bias, np.zeros((K, H), np.float32), np.zeros((K, H), np.float32))
        )
    sq_sum = torch.zeros(K, dtype=torch.float64)
    (i_in,), (i_out,) = net.chains["sensor_in"], net.chains["sensor_out"]
    with torch.no_grad():
        for i in range(0, n - 1, chunk):
            xs, xm = sensors[i : i + chunk], motors[i : i + chunk]  # predict steps i + 1 ..
            target = sensors[i + 1 : i + chunk + 1]  # one fewer at the end of the split
            pad = -len(xs) % ALIGN_ROWS
            if pad:
                xs, xm = (torch.cat([x, x.new_zeros(pad, x.shape[1])]) for x in (xs, xm))
            L = len(xs)
            x = linear(xs.expand(K, L, -1), *plan[i_in]).relu_()  # (K, L, 16)
            for wih, whh_t, bias, h, cell in layers:
                act = torch.bmm(x, wih.mT)  # (K, L, 4H)
                x = torch.empty(K, L, H)
                layer_sequence(act.numpy(), whh_t, bias, scale, h, cell, x.numpy())
            z = linear(x, *plan[i_out])  # (K, L, 10)
            if c.uses_motors:
                zm = net._forward(plan, "motor_encoder", xm.expand(K, L, -1))[-1]
                z = torch.cat([z, zm], dim=-1)  # (K, L, 15)
            pred = net._forward(plan, "predictor", z)[-1]  # (K, L, 5)
            diff = pred[:, : len(target)] - target
            sq_sum += diff.square().sum((1, 2)).double()
    return (sq_sum / (n - 1)).tolist()
