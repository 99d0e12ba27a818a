"""Several seeds of an encoder as one network with stacked weights, the backward pass by hand.

The stack (weights, gradients, Adam state of K seeds) serves all four models; the
feed-forward pass and epoch are here, the recurrent ones in ``stacked_lstm``, and
``engine.StackedEngine`` plugs them into the one training loop (``learn.train``).

A training step of S and SM is bound by per-operation overhead, not by arithmetic: a
tiny torch call costs a few microseconds on a CPU and autograd adds its own bookkeeping per
node. Here K seeds train as one network whose tensors carry a leading seed axis; each layer is
one ``baddbmm`` over all seeds and the backward pass is written out by hand (no autograd):

    forward    h' = relu(b + h W^T)                            (K, B, in) -> (K, B, out)
    backward   dW = dy^T h  (K, out, in)     db = sum_B dy  (K, 1, out)
               dh = (dy W) * [h' > 0]  for the layer below     (K, B, in)

with ``dy = 2 (pred - y) / B`` at the output: the gradient of the paper's error (squared error
summed over the 5 sensors, mean over the batch). Adam is elementwise, so one fused Adam step
(``private.adam_``) on stacked tensors gives every seed exactly the Adam of ``adam.FusedAdam``.

Nothing of the algorithm changes: each seed starts from ``models.build_model(kind, seed)``,
sees batches of 64 in its own order (``batches.epoch_generator``), keeps its own early stopping
and best weights, and gets a run folder identical to a single-seed run. A seed that stops
leaves the stack (it costs nothing more), and no seed's numbers depend on which seeds share
its stack (every operation treats the seeds independently; tests check it bit for bit).

Each product runs in the orientation the BLAS is fast at (``matmul``, ``linear``,
``weight_grad``): one with fewer than 16 columns, (64, 128) x (128, 10) say, runs as its
transpose (see ``products``). So a seed's numbers agree with its ``nn.Module`` trained alone with
autograd (``engine.train_epoch_feedforward``) to float32 rounding, not bit for bit, while they
stay bit for bit the same in a stack of K as alone (tests check both).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from sensorimotor.learn.batches import epoch_orders
from sensorimotor.learn.fast import cuda_graphs
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.private import adam_, relu_grad_
from sensorimotor.learn.fast.products import ALIGN_ROWS, linear, matmul, weight_grad
from sensorimotor.learn.models import ModelConfig, SensorimotorEncoder

CHUNK_BATCHES = 512  # batches gathered at once: K x 32,768 transitions, a few MB
ADAM_VECTOR = 16  # floats per SIMD vector, at most (AVX-512); see StackedEncoders._adam_lists


def model_layout(config: ModelConfig) -> tuple[list[str], list[torch.Size], list[str]]:
    """A model's parameter names and shapes, in ``parameters()`` order, and the names of its
    ``nn.Linear`` modules, in the same order."""
    with torch.device("meta"):
        model = SensorimotorEncoder(config)
    named = list(model.named_parameters())
    linears = [n for n, mod in model.named_modules() if isinstance(mod, torch.nn.Linear)]
    return [n for n, _ in named], [p.shape for _, p in named], linears


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
        adam_(params, grads, exp_avg, exp_avg_sq, [self.step] * len(params), self.lr)

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
        """Seed ``k``'s Adam state in ``adam.FusedAdam.state_dict()``'s format."""
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

    def _backward(self, plan, grads, chain: str, hs, dy: torch.Tensor, input_grad=False, add=False):
        """Fill the gradients of one chain's layers (``add``: add to them, for a chain applied
        several times); return d/d(chain input) if asked."""
        layers = self.chains[chain]
        for j in range(len(layers) - 1, -1, -1):
            i = layers[j]
            w = plan[i][0]  # (K, out, in)
            h = hs[j]  # (K, B, in): input of layer i
            wi, bi = self.linear_index[i]
            weight_grad(dy, h, grads[wi], add)  # (K, out, in) = dy^T h
            if add:
                grads[bi].add_(dy.sum(1, keepdim=True))
            else:
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
                cuda_graphs.replay_stacked(steps, net)
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
