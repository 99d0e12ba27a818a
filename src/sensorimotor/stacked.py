"""Several seeds of an encoder trained at once, through stacked weights, into run folders.

The stack (weights, gradients, Adam state of K seeds) and the run-folder loop (``train_runs``:
per-seed early stopping, checkpoints, resume) serve all four models; the feed-forward pass is
here, the recurrent one in ``stacked_lstm``.

A training step of S and SM is bound by per-operation overhead, not by arithmetic: a
tiny torch call costs a few microseconds on a CPU and autograd adds its own bookkeeping per
node. Here K seeds train as one network whose tensors carry a leading seed axis; each layer is
one ``baddbmm`` over all seeds and the backward pass is written out by hand (no autograd):

    forward    h' = relu(b + h W^T)                            (K, B, in) -> (K, B, out)
    backward   dW = dy^T h  (K, out, in)     db = sum_B dy  (K, 1, out)
               dh = (dy W) * [h' > 0]  for the layer below     (K, B, in)

with ``dy = 2 (pred - y) / B`` at the output: the gradient of the paper's error (squared error
summed over the 5 sensors, mean over the batch). Adam is elementwise, so ``torch._fused_adam_``
on stacked tensors gives every seed exactly the Adam of ``train.FusedAdam``.

Nothing of the algorithm changes: each seed starts from ``models.build_model(kind, seed)``,
sees batches of 64 in its own order (``train.epoch_generator``), keeps its own early stopping
and best weights, and gets a run folder identical to a single-seed run. A seed that stops
leaves the stack (it costs nothing more), and no seed's numbers depend on which seeds share
its stack (every operation treats the seeds independently; tests check it bit for bit).

Each product runs in the orientation the BLAS is fast at (``matmul``, ``linear``,
``weight_grad``): one with fewer than 16 columns, (64, 128) x (128, 10) say, runs as its
transpose, up to 6x faster. So a seed's numbers agree with its ``nn.Module`` trained alone with
autograd (``train.train_epoch_feedforward``) to float32 rounding, not bit for bit, while they
stay bit for bit the same in a stack of K as alone (tests check both).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import torch

from sensorimotor import cuda_graphs
from sensorimotor import train as train_mod
from sensorimotor.data import Database, database_file, load_database
from sensorimotor.errors import InputError
from sensorimotor.evaluate import split_tensors
from sensorimotor.models import ModelConfig, SensorimotorEncoder, build_model
from sensorimotor.runs import (
    EarlyStopping,
    EpochRecord,
    TrainConfig,
    TrainResult,
    check_run_dir,
    finish_run,
    load_checkpoint,
    open_run_dir,
    run_meta,
    run_name,
    save_epoch,
    stored_result,
)
from sensorimotor.train import (
    FusedAdam,
    check_trainable,
    epoch_generator,
    resolve_device,
    stop_reason,
)

CHUNK_BATCHES = 512  # batches gathered at once: K x 32,768 transitions, a few MB
ALIGN_ROWS = 16  # gathered rows padded to a multiple of this: 64-byte aligned seed slabs
ADAM_VECTOR = 16  # floats per SIMD vector, at most (AVX-512); see StackedEncoders._adam_lists
NARROW = 16  # a product with fewer columns than this runs as its transpose (see matmul)
TALL = 512  # from this many rows on, a weight gradient runs as its transpose (weight_grad)

# (which run: its seed for train_seeds, its index in runs for train_runs; record, stopper)
OnEpoch = Callable[[int, EpochRecord, EarlyStopping], None]


def check_seeds(seeds: Sequence[int]) -> list[int]:
    """Refuse an empty list or a repeated seed."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise InputError("--seeds: give at least one seed, e.g. 0,1,2,3,4")
    for i, s in enumerate(seeds):
        if s in seeds[:i]:
            raise InputError(f"--seeds: seed {s} is given twice")
    return seeds


def trains_stacked(model: str, device: str) -> bool:
    """Whether ``train_runs`` trains ``model`` on ``device`` ("auto", "cpu", "cuda"): every
    model but the recurrent ones on CUDA (the stacked LSTM's kernels are CPU code), as long as
    the stack computes what ``models.py`` does (``computes_models_py``)."""
    on_cpu = resolve_device(device) == "cpu"
    return (on_cpu or not ModelConfig(kind=model).recurrent) and computes_models_py(model)


# the layers the hand-written passes know, taken at import (before anything can patch torch.nn)
_KNOWN_LAYERS = (torch.nn.Sequential, torch.nn.Linear, torch.nn.ReLU, torch.nn.LSTM)


def _known_layers(module: SensorimotorEncoder) -> bool:
    """Whether every submodule is one the stack computes: Linear (with bias), ReLU, and a
    plain LSTM (batch first, biases, no dropout, projection or second direction)."""
    for layer in list(module.modules())[1:]:  # the encoder itself aside
        if type(layer) not in _KNOWN_LAYERS:
            return False
        if isinstance(layer, torch.nn.Linear) and layer.bias is None:
            return False
        if isinstance(layer, torch.nn.LSTM) and (
            not layer.batch_first
            or not layer.bias
            or layer.dropout
            or layer.bidirectional
            or layer.proj_size
        ):
            return False
    return True


@functools.cache
def computes_models_py(model: str) -> bool:
    """Whether the stack's hand-written passes compute what ``models.py`` computes for
    ``model``, checked once per process: its layers are those the passes know
    (``_known_layers``), and two steps (recurrent: two chunks, the state carried) give the
    loss and every gradient of autograd through the ``nn.Module``, to float32 rounding, on
    inputs ten times wider than the data's so that activations leave the range a fresh model
    sees. A model edited in ``models.py`` that fails this trains with autograd instead
    (``train.train``). Tens of ms, and the first load of the numba kernels (about a second)."""
    from sensorimotor.stacked_lstm import forward_backward as recurrent_forward_backward

    module = build_model(model, seed=0)
    if not _known_layers(module):
        return False
    c = module.config
    try:
        net = StackedEncoders.from_models([module])
    except (KeyError, ValueError, RuntimeError):  # parameters the stack cannot lay out
        return False
    gen = torch.Generator().manual_seed(0)
    t, b = (5, 8) if c.recurrent else (1, 32)  # time steps, streams or batch
    state = module_state = None
    for _ in range(2):
        xs = torch.rand(t, b, c.n_sensors, generator=gen) * 20 - 5  # (T, B, 5), time first
        xm = torch.rand(t, b, c.n_motors, generator=gen) * 20 - 10
        y = torch.rand(t, b, c.n_sensors, generator=gen)
        sq_sum = torch.zeros(1)
        try:
            if c.recurrent:
                state = recurrent_forward_backward(net, xs, xm, y, None, state, sq_sum)
            else:
                net.forward_backward(xs, xm, y, sq_sum.view(1, 1, 1))
        except (KeyError, ValueError, RuntimeError):
            return False
        module.zero_grad()
        pred, _, module_state = module(xs.transpose(0, 1), xm.transpose(0, 1), module_state)
        if module_state is not None:
            module_state = tuple(h.detach() for h in module_state)  # truncated, as training
        loss = (pred - y.transpose(0, 1)).square().sum(-1).mean()
        loss.backward()
        if not torch.allclose(sq_sum, loss.detach() * t * b, rtol=1e-4):
            return False
        for g, p in zip(net.grads, module.parameters(), strict=True):
            if (g.reshape(p.shape) - p.grad).abs().max() > 1e-4 * p.grad.abs().max() + 1e-7:
                return False
    return True


def model_layout(config: ModelConfig) -> tuple[list[str], list[torch.Size], list[str]]:
    """A model's parameter names and shapes, in ``parameters()`` order, and the names of its
    ``nn.Linear`` modules, in the same order."""
    with torch.device("meta"):
        model = SensorimotorEncoder(config)
    named = list(model.named_parameters())
    linears = [n for n, mod in model.named_modules() if isinstance(mod, torch.nn.Linear)]
    return [n for n, _ in named], [p.shape for _, p in named], linears


_THRESHOLD_BACKWARD = torch.ops.aten.threshold_backward.grad_input


def relu_grad_(dy: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """dy zeroed where the ReLU output h is not positive, in place: autograd's ReLU backward
    in one call, with no new multi-MB output."""
    return _THRESHOLD_BACKWARD(dy, h, 0, grad_input=dy)


# --- batched products, each seed its own matrices ------------------------------------------
# The BLAS (MKL here) is several times slower on a tall product with few columns, (1280, 128)
# x (128, 10) say, than on its transpose: 2.1 ms against 0.32 for K = 5 on this machine's
# CPU. So a product narrower than NARROW columns is computed as its transpose, and the result
# is a transposed view; the caller never sees the difference but in the strides.


def matmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """a @ b for (K, M, n) x (K, n, N)."""
    if b.shape[-1] < NARROW <= a.shape[-2]:
        return torch.bmm(b.mT, a.mT).mT
    return torch.bmm(a, b)


def linear(h: torch.Tensor, w: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """b + h W^T, as F.linear: h (K, B, in), w (K, out, in), b (K, 1, out)."""
    if w.shape[-2] < NARROW <= h.shape[-2]:
        return torch.baddbmm(b.mT, w, h.mT).mT
    return torch.baddbmm(b, h, w.mT)


def weight_grad(dy: torch.Tensor, h: torch.Tensor, out: torch.Tensor) -> None:
    """out (K, out, in) = dy^T h, for dy (K, B, out) and h (K, B, in). Over a tall B (a
    recurrent chunk's 1,280 steps) the product with fewer rows is faster (0.69 ms against
    0.83 for K = 5, in = 32, out = 128), and the copy into out costs little."""
    if h.shape[-1] < NARROW <= dy.shape[-1] or (h.shape[-2] >= TALL and h.shape[-1] < dy.shape[-1]):
        out.copy_(torch.bmm(h.mT, dy).mT)
    else:
        torch.bmm(dy.mT, h, out=out)


# --- the stack: weights, gradients and Adam state of K seeds -------------------------------


class StackedEncoders:
    """K encoders of one kind: weights, gradients and Adam state.

    ``params`` follows ``SensorimotorEncoder.parameters()``, each with a leading seed axis:
    a matrix (an ``nn.Linear`` or LSTM weight) as ``(K, out, in)``, a bias as ``(K, 1, out)``.
    ``grads`` are preallocated alike; all seeds have taken ``step`` Adam steps. The
    feed-forward pass below is for S and SM; ``stacked_lstm`` runs Rec-S and Rec-SM.
    """

    def __init__(
        self,
        config: ModelConfig,
        params: list[torch.Tensor],
        exp_avg: list[torch.Tensor],
        exp_avg_sq: list[torch.Tensor],
        step: float,
        lr: float = 1e-3,
    ):
        self.config, self.lr = config, lr
        self.params, self.exp_avg, self.exp_avg_sq = params, exp_avg, exp_avg_sq
        self.step = torch.full((), float(step), device=params[0].device)  # float32, as FusedAdam
        self.names, self.shapes, linears = model_layout(config)
        self.index = index = {name: i for i, name in enumerate(self.names)}  # name -> position
        self.chains: dict[str, list[int]] = {}  # "sensor_encoder" -> its layers, in order
        self.linear_index: list[tuple[int, int]] = []  # (weight, bias) of each nn.Linear
        for i, name in enumerate(linears):
            self.chains.setdefault(name.split(".")[0], []).append(i)
            self.linear_index.append((index[f"{name}.weight"], index[f"{name}.bias"]))
        self._prepare()

    @property
    def k(self) -> int:
        return self.params[0].shape[0]

    @classmethod
    def from_models(
        cls,
        models: Sequence[SensorimotorEncoder],
        optimizers: Sequence[FusedAdam] | None = None,
        lr: float = 1e-3,
    ) -> StackedEncoders:
        """Stack ``models`` (one feed-forward kind) and, if given, their ``FusedAdam`` states."""
        config = models[0].config

        def stack(per_model: list[list[torch.Tensor]]) -> list[torch.Tensor]:
            out = []
            for tensors in zip(*per_model, strict=True):
                t = torch.stack([x.detach() for x in tensors])  # (K, out, in) | (K, out)
                out.append(t if t.dim() == 3 else t[:, None, :].contiguous())
            return out

        params = stack([list(m.parameters()) for m in models])
        if optimizers is None:
            zeros = [torch.zeros_like(p) for p in params]
            return cls(config, params, zeros, [z.clone() for z in zeros], 0, lr)
        steps = {float(opt.steps[0]) for opt in optimizers}
        if len(steps) != 1:
            raise ValueError(f"seeds at different Adam steps cannot share a stack: {steps}")
        exp_avg = stack([opt.exp_avg for opt in optimizers])
        exp_avg_sq = stack([opt.exp_avg_sq for opt in optimizers])
        return cls(config, params, exp_avg, exp_avg_sq, steps.pop(), lr)

    def _prepare(self) -> None:
        """Gradient buffers, the weight views of each product, and Adam's tensor lists."""
        self.grads = [torch.empty_like(p) for p in self.params]
        self.graphs: dict = {}  # CUDA graphs of steps on these tensors (cuda_graphs)
        # per nn.Linear: weight (K, out, in), bias (K, 1, out)
        self.layers = [(self.params[w], self.params[b]) for w, b in self.linear_index]
        self._adam = [self._adam_lists(t) for t in (self.params, self.grads)]
        self._adam += [self._adam_lists(t) for t in (self.exp_avg, self.exp_avg_sq)]

    def _adam_lists(self, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
        """Each tensor whole, or seed by seed where one seed's size is not a whole number of
        SIMD vectors: the fused kernel runs a vector loop then a scalar tail (the two round
        differently), and each seed's elements must fall in the loop they fall in alone."""
        out = []
        for t in tensors:
            if t[0].numel() % ADAM_VECTOR == 0:
                out.append(t)
            else:
                out.extend(t.unbind(0))
        return out

    def adam_step(self) -> None:
        """One Adam step of every seed (learning rate ``lr``, betas 0.9, 0.999, eps 1e-8)."""
        self.step.add_(1)
        params, grads, exp_avg, exp_avg_sq = self._adam
        torch._fused_adam_(
            params,
            grads,
            exp_avg,
            exp_avg_sq,
            [],
            [self.step] * len(params),
            lr=self.lr,
            beta1=0.9,
            beta2=0.999,
            weight_decay=0.0,
            eps=1e-8,
            amsgrad=False,
            maximize=False,
        )

    def select(self, index: Sequence[int]) -> None:
        """Keep only the seeds at ``index``, in that order (a stopped seed leaves the stack)."""
        idx = torch.tensor(list(index), dtype=torch.long, device=self.step.device)
        for name in ("params", "exp_avg", "exp_avg_sq"):
            setattr(self, name, [t.index_select(0, idx) for t in getattr(self, name)])
        self._prepare()

    @classmethod
    def concat(cls, stacks: Sequence[StackedEncoders]) -> StackedEncoders:
        """One stack of the seeds of ``stacks`` (all at the same Adam step), in that order."""
        first = stacks[0]
        if len({float(s.step) for s in stacks}) != 1:
            raise ValueError("stacks at different Adam steps cannot merge")

        def cat(name: str) -> list[torch.Tensor]:
            return [torch.cat(ts) for ts in zip(*(getattr(s, name) for s in stacks), strict=True)]

        return cls(
            first.config,
            cat("params"),
            cat("exp_avg"),
            cat("exp_avg_sq"),
            float(first.step),
            first.lr,
        )

    def _per_seed(self, tensors: list[torch.Tensor], k: int) -> list[torch.Tensor]:
        """Copies of seed ``k``'s slice of stacked tensors, shaped as the model's parameters."""
        return [t[k].reshape(shape).clone() for t, shape in zip(tensors, self.shapes, strict=True)]

    def load_into(self, k: int, model: SensorimotorEncoder) -> SensorimotorEncoder:
        """Copy seed ``k``'s weights into ``model`` (same kind); returns it."""
        with torch.no_grad():
            for p, src in zip(model.parameters(), self._per_seed(self.params, k), strict=True):
                p.copy_(src)
        return model

    def optimizer_state(self, k: int) -> dict:
        """Seed ``k``'s Adam state in ``train.FusedAdam.state_dict()``'s format."""
        return {
            "exp_avg": self._per_seed(self.exp_avg, k),
            "exp_avg_sq": self._per_seed(self.exp_avg_sq, k),
            "steps": [self.step.clone() for _ in self.params],
        }

    # --- the network, forward and backward -------------------------------------------------

    def _forward(self, plan, chain: str, h: torch.Tensor) -> list[torch.Tensor]:
        """The input of every layer of one chain, then its output (ReLU after all but last)."""
        hs = [h]
        layers = self.chains[chain]
        for i in layers:
            h = linear(h, *plan[i])  # (K, B, out)
            if i != layers[-1]:
                h = h.relu_()
            hs.append(h)
        return hs

    def _backward(self, plan, grads, chain: str, hs, dy: torch.Tensor, input_grad=False):
        """Fill the gradients of one chain's layers; return d/d(chain input) if asked."""
        layers = self.chains[chain]
        for j in range(len(layers) - 1, -1, -1):
            i = layers[j]
            w = plan[i][0]  # (K, out, in)
            h = hs[j]  # (K, B, in): input of layer i
            wi, bi = self.linear_index[i]
            weight_grad(dy, h, grads[wi])  # (K, out, in) = dy^T h
            torch.sum(dy, 1, keepdim=True, out=grads[bi])  # (K, 1, out)
            if j:
                dy = relu_grad_(matmul(dy, w), h)  # (K, B, in); h is a ReLU output
            elif input_grad:
                return matmul(dy, w)  # (K, B, in)
        return None

    def forward_backward(
        self, xs: torch.Tensor, xm: torch.Tensor | None, y: torch.Tensor, sq_sum: torch.Tensor
    ) -> None:
        """One batch: each seed's loss gradient into ``grads``; each seed's summed squared
        error added to ``sq_sum`` (K, 1, 1).

        xs (K, B, 5) sensors, xm (K, B, 2) motors (SM; None for S), y (K, B, 5) next sensors.
        A batch of a size other than a multiple of 16 (the last of an epoch) runs seed by
        seed: there, a seed's slab of a stacked result would not start on a 64-byte boundary,
        and the BLAS may then sum in another order than for the seed alone.
        """
        if xs.shape[1] % ALIGN_ROWS == 0 or self.k == 1:
            self._forward_backward(self.layers, self.grads, xs, xm, y, sq_sum)
            return
        for k in range(self.k):
            plan = [tuple(t[k : k + 1] for t in layer) for layer in self.layers]
            grads = [g[k : k + 1] for g in self.grads]
            xm_k = None if xm is None else xm[k : k + 1]
            self._forward_backward(
                plan, grads, xs[k : k + 1], xm_k, y[k : k + 1], sq_sum[k : k + 1]
            )

    def _forward_backward(self, plan, grads, xs, xm, y, sq_sum) -> None:
        hs = self._forward(plan, "sensor_encoder", xs)  # [(K, B, 5), ..., z_s (K, B, 10)]
        z = hs[-1]
        if self.config.uses_motors:
            hm = self._forward(plan, "motor_encoder", xm)  # [(K, B, 2), ..., z_m (K, B, 5)]
            z = torch.cat([z, hm[-1]], dim=-1)  # (K, B, 15)
        hp = self._forward(plan, "predictor", z)  # [(K, B, 15), (K, B, 128), pred (K, B, 5)]
        diff = hp[-1].sub_(y)  # (K, B, 5)
        k, b = diff.shape[0], diff.shape[1]
        d = diff.reshape(k, -1)  # a copy where diff is a transposed view (see matmul)
        sq_sum.baddbmm_(d[:, None, :], d[:, :, None])  # += sum of squares
        dy = diff.mul_(2.0 / b)  # d/dpred of mean_B sum_5 (pred - y)^2; exact in float32
        dz = self._backward(plan, grads, "predictor", hp, dy, input_grad=True)  # (K, B, 10|15)
        if self.config.uses_motors:
            zs = self.config.z_sensors
            self._backward(plan, grads, "motor_encoder", hm, dz[..., zs:])
            dz = dz[..., :zs]
        self._backward(plan, grads, "sensor_encoder", hs, dz)

    @torch.no_grad()
    def predict(self, xs: torch.Tensor, xm: torch.Tensor | None = None) -> torch.Tensor:
        """Each seed's prediction (K, B, 5) from its own inputs (K, B, 5), (K, B, 2)."""
        z = self._forward(self.layers, "sensor_encoder", xs)[-1]
        if self.config.uses_motors:
            z = torch.cat([z, self._forward(self.layers, "motor_encoder", xm)[-1]], dim=-1)
        return self._forward(self.layers, "predictor", z)[-1]


# --- one epoch -----------------------------------------------------------------------------


def epoch_orders(n: int, seeds: Sequence[int], epoch: int) -> torch.Tensor:
    """Each seed's data order of one epoch, drawn as ``train.train_epoch_feedforward`` draws
    it: ``torch.randperm(n, generator=epoch_generator(seed, epoch))``; (K, n) indices."""
    return torch.stack([torch.randperm(n, generator=epoch_generator(s, epoch)) for s in seeds])


def train_epoch_stacked(
    net: StackedEncoders,
    s: torch.Tensor,
    m: torch.Tensor,
    seeds: Sequence[int],
    epoch: int,
    batch: int,
    splits: Sequence[int] | None = None,
) -> torch.Tensor:
    """One epoch of every seed of ``net`` over its own shuffled transitions.

    s (n + 1, 5), m (n + 1, 2): the train split; row k of the stack is seed ``seeds[k]``.
    Or s (W, n + 1, 5), m (W, n + 1, 2): W train splits of one length (W databases), seed k
    training on split ``splits[k]``. Each seed's transitions are gathered once per chunk of
    batches, so a batch is a view. Returns each seed's mean training error (K,), on the device
    (no host synchronisation).
    """
    if net.k != len(seeds):
        raise ValueError(f"{len(seeds)} seeds for a stack of {net.k}")
    n = s.shape[-2] - 1
    order = epoch_orders(n, seeds, epoch).to(s.device)  # (K, n)
    if s.dim() == 3:  # one tensor of all splits; a seed's rows start where its split does
        if splits is None or len(splits) != net.k:
            raise ValueError("several train splits need one split index per seed")
        start = torch.tensor(list(splits), device=s.device) * (n + 1)
        order += start[:, None]
        s, m = s.reshape(-1, s.shape[-1]), m.reshape(-1, m.shape[-1])
    s0, m0, s1 = s[:-1], m[:-1], s[1:]  # a transition never crosses two splits
    motors = net.config.uses_motors
    sq_sum = torch.zeros(net.k, 1, 1, device=s.device)
    start = 0  # transitions done by CUDA graphs
    with torch.no_grad():
        if cuda_graphs.enabled(s):
            steps = cuda_graphs.stacked_steps(net, batch)
            sq_sum = steps.sq_sum.zero_()
            rows = cuda_graphs.GRAPH_BATCHES * batch
            for start in range(0, n - rows + 1, rows):
                idx = order[:, start : start + rows].reshape(-1)  # (K rows)
                for buf, src in ((steps.x, s0), (steps.xm, m0), (steps.y, s1)):
                    if buf is not None:
                        torch.index_select(src, 0, idx, out=buf.view(-1, buf.shape[-1]))
                cuda_graphs.run_stacked(steps, net)
            start = n // rows * rows
        chunk = batch * CHUNK_BATCHES
        for c in range(start, n, chunk):
            idx = order[:, c : c + chunk]  # (K, c)
            size, pad = idx.shape[1], -idx.shape[1] % ALIGN_ROWS
            if pad:  # each seed's rows start on a 64-byte boundary, as they do alone
                idx = torch.cat([idx, idx.new_zeros(net.k, pad)], dim=1)  # (K, c + pad)
            xs = s0[idx][:, :size].split(batch, dim=1)  # (K, b, 5) views of one gather
            ys = s1[idx][:, :size].split(batch, dim=1)  # (K, b, 5)
            xms = m0[idx][:, :size].split(batch, dim=1) if motors else [None] * len(xs)
            for x, xm, y in zip(xs, xms, ys, strict=True):
                net.forward_backward(x, xm, y, sq_sum)
                net.adam_step()
    return sq_sum.view(-1) / n


# --- run folders ---------------------------------------------------------------------------


@dataclass
class _Run:
    """One seed's run folder and where its training stands."""

    index: int  # in train_runs' runs
    seed: int
    out: Path
    split: int  # which database (train_runs' data) it trains on
    model: SensorimotorEncoder  # scratch copy: validation and saving
    stopper: EarlyStopping
    history: list[EpochRecord] = field(default_factory=list)
    epoch: int = 0  # the next epoch to train
    elapsed: float = 0.0
    result: TrainResult | None = None


@train_mod.flush_subnormals()
def train_runs(
    data: str | Path | Database | Sequence[str | Path | Database],
    runs: Sequence[tuple[int, str | Path]],
    config: TrainConfig,
    resume: bool = False,
    on_epoch: OnEpoch | None = None,
) -> list[TrainResult]:
    """Train one model per ``(seed, run folder)`` in ``runs``, all seeds in one stack.

    ``data``: one database for every run, or one per run (S and SM: the stack then spans
    databases, e.g. worlds, of one size). Every run folder is what ``train.train(data, out,
    replace(config, seed=seed))`` writes; ``config.seed`` is not used. With ``resume``, each run
    continues from its checkpoint; seeds left at different epochs (a kill between two seeds'
    checkpoints) train in separate stacks, the lagging one first, and merge once caught up.
    """
    if isinstance(data, (str, Path, Database)):
        data = [data] * len(runs)
    paths = [database_file(d) for d in data]
    if len(paths) != len(runs):
        raise ValueError(f"{len(paths)} databases for {len(runs)} runs")
    files = list(dict.fromkeys(paths))  # each database once, in order
    split_of = [files.index(p) for p in paths]
    device = resolve_device(config.device)
    config = replace(config, device=device)
    model_config = ModelConfig(kind=config.model)
    if not computes_models_py(config.model):
        raise ValueError(
            f"models.py's {config.model} is not what the stack computes: train it with train.train"
        )
    if not trains_stacked(config.model, device):
        raise ValueError(
            "the stacked LSTM is CPU only: train recurrent models on CUDA with train.train"
        )
    if model_config.recurrent and len(files) > 1:
        raise ValueError("a recurrent stack trains on one database")
    seeds = [int(seed) for seed, _ in runs]
    for f in files or [None]:  # at least one seed, and distinct ones on each database
        check_seeds([sd for sd, p in zip(seeds, paths, strict=True) if p == f])
    outs = [Path(out) for _, out in runs]
    if len(set(outs)) != len(outs):
        raise ValueError("two runs share a run folder")
    dbs = [load_database(f) for f in files]
    for db in dbs:
        check_trainable(db, config)
    if len({len(db.take("train")) for db in dbs}) > 1:
        raise ValueError("databases of a stack must have train splits of one length")
    sha: dict[int, str] = {}
    metas = []
    for seed, out, w in zip(seeds, outs, split_of, strict=True):
        meta = run_meta(files[w], dbs[w], replace(config, seed=seed), sha.get(w))
        sha[w] = meta["data"]["sha256"]
        check_run_dir(out, meta, resume)  # every folder checked before any is written
        metas.append(meta)
    for out, meta in zip(outs, metas, strict=True):
        open_run_dir(out, meta)

    torch.set_num_threads(config.threads)
    train_mod.keep_freed_memory()
    state: list[_Run] = []
    opts: list[FusedAdam] = []
    for i, (seed, out, w) in enumerate(zip(seeds, outs, split_of, strict=True)):
        model = build_model(model_config, seed=seed).to(device)
        opt = FusedAdam(model.parameters(), lr=config.lr)
        run = _Run(i, seed, out, w, model, EarlyStopping(config.patience, config.min_ratio))
        if resume and (out / "checkpoint.pt").exists():
            run.stopper, run.history, run.epoch, run.elapsed = load_checkpoint(
                out, device, model, opt
            )
            run.result = stored_result(out, run.history)
        state.append(run)
        opts.append(opt)

    train_splits = [split_tensors(db, "train", device) for db in dbs]
    val = [split_tensors(db, "val", device) for db in dbs]
    if len(dbs) == 1:
        s, m = train_splits[0]
    else:  # (W, n + 1, .): one gather serves every database
        s, m = (torch.stack(t) for t in zip(*train_splits, strict=True))
    del train_splits
    n = s.shape[-2] - 1
    stacks: list[tuple[list[_Run], StackedEncoders]] = []  # seeds at one epoch, and their stack
    by_epoch: dict[int, list[int]] = {}
    for i, run in enumerate(state):
        if run.result is None:
            by_epoch.setdefault(run.epoch, []).append(i)
    for idx in by_epoch.values():
        net = StackedEncoders.from_models(
            [state[i].model for i in idx], [opts[i] for i in idx], lr=config.lr
        )
        stacks.append(([state[i] for i in idx], net))

    while True:
        stacks = [_drop_finished(config, members, net) for members, net in stacks]
        stacks = _merge_same_epoch([st for st in stacks if st[0]])
        if not stacks:
            break
        members, net = min(stacks, key=lambda st: st[0][0].epoch)  # the lagging stack first
        epoch = members[0].epoch
        t0 = time.perf_counter()
        if model_config.recurrent:
            from sensorimotor.stacked_lstm import sequence_errors, train_epoch_stacked_recurrent

            errors = train_epoch_stacked_recurrent(net, s, m, config.batch_size, config.horizon)
        else:
            order = [r.seed for r in members]  # each seed's own data order
            splits = [r.split for r in members]
            errors = train_epoch_stacked(net, s, m, order, epoch, config.batch_size, splits)
        train_errors = errors.tolist()
        seconds = time.perf_counter() - t0  # training alone: the record's samples/s
        for k, run in enumerate(members):
            net.load_into(k, run.model)  # validated (feed-forward) and saved below
        if model_config.recurrent:  # every seed at once, as train.model_error does each
            val_errors = sequence_errors(net, *val[0])  # a recurrent stack: one database
        else:
            val_errors = [train_mod.model_error(run.model, *val[run.split]) for run in members]
        stack_seconds = time.perf_counter() - t0  # charged to each seed, as its epoch's time
        for k, run in enumerate(members):
            t1 = time.perf_counter()
            val_error = val_errors[k]
            improved, best = run.stopper.update(epoch, val_error)
            run.elapsed += stack_seconds + time.perf_counter() - t1
            record = EpochRecord(
                epoch, train_errors[k], val_error, improved, best, seconds, n / seconds, run.elapsed
            )
            run.history.append(record)
            save_epoch(
                run.out,
                run.model,
                net.optimizer_state(k),
                epoch,
                run.elapsed,
                run.stopper,
                run.history,
            )
            run.epoch += 1
            if on_epoch is not None:
                on_epoch(run.index, record, run.stopper)
    return [run.result for run in state]


def _drop_finished(config: TrainConfig, members: list[_Run], net: StackedEncoders):
    """Finish the runs that stop before their next epoch; the others stay in the stack."""
    keep = []
    for k, run in enumerate(members):
        reason = stop_reason(config, run.stopper, run.epoch, run.elapsed)
        if reason is None:
            keep.append(k)
        else:
            run.result = finish_run(run.out, run.stopper, run.history, reason, run.elapsed)
    if 0 < len(keep) < len(members):
        net.select(keep)
    return [members[k] for k in keep], net


def _merge_same_epoch(stacks):
    """Stacks whose seeds have reached the same epoch become one."""
    by_epoch: dict[int, list] = {}
    for st in stacks:
        by_epoch.setdefault(st[0][0].epoch, []).append(st)
    merged = []
    for group in by_epoch.values():
        if len(group) == 1:
            merged.append(group[0])
        else:
            members = [r for mem, _ in group for r in mem]
            merged.append((members, StackedEncoders.concat([net for _, net in group])))
    return merged


def train_seeds(
    data: str | Path | Database,
    out: str | Path,
    config: TrainConfig,
    seeds: Sequence[int],
    resume: bool = False,
    on_epoch: OnEpoch | None = None,
) -> list[TrainResult]:
    """Train one model per seed into ``out/{world}__{model}__s{seed}`` run folders.

    All seeds at once in one stack (``train_runs``); recurrent models on CUDA, where
    ``nn.LSTM`` runs cuDNN, one seed after another (``train.train``), into the same folders.
    """
    seeds = check_seeds(seeds)
    data, out = database_file(data), Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    world = load_database(data).meta["world"]["name"]
    runs = [(seed, out / run_name(world, config.model, seed)) for seed in seeds]
    if trains_stacked(config.model, config.device):
        by_index = None if on_epoch is None else (lambda i, r, st: on_epoch(seeds[i], r, st))
        return train_runs(data, runs, config, resume, by_index)
    results = []
    for seed, run_dir in runs:
        callback = None if on_epoch is None else (lambda r, st, seed=seed: on_epoch(seed, r, st))
        results.append(train_mod.train(data, run_dir, replace(config, seed=seed), resume, callback))
    return results
