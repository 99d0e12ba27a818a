"""Several seeds of a feed-forward encoder (S, SM) trained at once through stacked weights.

Training these encoders one batch of 64 at a time is bound by per-operation overhead, not by
arithmetic: a tiny torch call costs a few microseconds on a CPU, and autograd adds its own
bookkeeping per node. This module trains K seeds as one network whose weights carry a leading
seed axis: ``W (K, out, in)``, ``b (K, 1, out)``; each layer is one ``baddbmm`` over all seeds,
and the backward pass is written out by hand (no autograd):

    forward    h' = relu(b + h W^T)                       (K, B, in) -> (K, B, out)
    backward   dW = dy^T h   (K, out, in)      db = sum_B dy   (K, 1, out)
               dh = (dy W) * [h > 0]                      (K, B, in)

The loss gradient of the paper's error (squared error summed over the 5 sensors, mean over the
batch) is ``dy = 2 (pred - y) / B``. The operations and operand layouts are those autograd uses
for ``nn.Linear``, so every seed's gradients equal, bit for bit, those of the ``nn.Module``
trained alone (a test checks it). Adam is elementwise: the fused kernel on stacked tensors gives
each seed exactly its own Adam (``train.FusedAdam``).

Nothing else changes: each seed sees batches of 64 from its own data order
(``train.epoch_generator``), starts from its own ``models.build_model(kind, seed)``, keeps its
own early stopping and best weights, and writes a run folder identical to a single-seed run.
A seed that stops leaves the stack, so it costs nothing more and the others are unaffected
(a seed's numbers do not depend on which seeds share its stack). After a kill, seeds may be at
different epochs: the stack that lags trains alone until it has caught up, then they merge.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from sensorimotor.errors import InputError
from sensorimotor.models import ModelConfig, SensorimotorEncoder

RELU_GRAD = torch.ops.aten.threshold_backward.default  # autograd's ReLU backward, one call
CHUNK_BATCHES = 512  # batches gathered at once: bounds memory at K x 32,768 transitions
FEEDFORWARD = ("s", "sm")


def run_name(world: str, model: str, seed: int) -> str:
    """Name of one run folder under a multi-seed ``--out`` (CleanRL's ``world__model__sSEED``)."""
    return f"{world}__{model}__s{seed}"


def check_seeds(seeds: Sequence[int]) -> list[int]:
    """Refuse an empty list or a repeated seed; returns the seeds as a list of ints."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise InputError("--seeds: give at least one seed, e.g. 0,1,2,3,4")
    seen = set()
    for s in seeds:
        if s in seen:
            raise InputError(f"--seeds: seed {s} is given twice")
        seen.add(s)
    return seeds


class StackedEncoders:
    """K feed-forward encoders of one kind (S or SM), their weights stacked on a seed axis.

    ``params`` follows ``SensorimotorEncoder.parameters()``: for every ``nn.Linear`` its weight
    ``(K, out, in)`` then its bias ``(K, 1, out)``. ``grads`` are preallocated alike and
    filled by :meth:`backward`, so the optimiser's lists never change during an epoch.
    """

    def __init__(self, config: ModelConfig, params: list[torch.Tensor]):
        if config.recurrent:
            raise ValueError(f"stacked training is for s and sm, not {config.kind}")
        self.config = config
        self.params = params
        self.grads = [torch.empty_like(p) for p in params]
        names = linear_names(config)
        if len(params) != 2 * len(names):
            raise ValueError(f"{config.kind}: expected {2 * len(names)} tensors, got {len(params)}")
        self.groups: dict[str, list[int]] = {}  # "sensor_encoder" -> indices of its layers
        for i, name in enumerate(names):
            self.groups.setdefault(name.split(".")[0], []).append(i)

    @property
    def k(self) -> int:
        return self.params[0].shape[0]

    @classmethod
    def from_models(cls, models: Sequence[SensorimotorEncoder]) -> StackedEncoders:
        """Stack the weights of ``models`` (all of one feed-forward kind), in that order."""
        per_model = [[p.detach() for p in m.parameters()] for m in models]
        params = []
        for tensors in zip(*per_model, strict=True):
            stacked = torch.stack(tensors)  # (K, out, in) | (K, out)
            params.append(stacked if stacked.dim() == 3 else stacked[:, None, :].contiguous())
        return cls(models[0].config, params)

    def load_into(self, k: int, model: SensorimotorEncoder) -> SensorimotorEncoder:
        """Copy seed ``k``'s weights into ``model`` (same kind); returns it."""
        with torch.no_grad():
            for p, src in zip(model.parameters(), self.params, strict=True):
                p.copy_(src[k].reshape(p.shape))
        return model

    def select(self, index: Sequence[int]) -> None:
        """Keep only the seeds at ``index`` (in that order): a stopped seed leaves the stack."""
        idx = torch.tensor(list(index), dtype=torch.long, device=self.params[0].device)
        self.params = [p.index_select(0, idx) for p in self.params]
        self.grads = [torch.empty_like(p) for p in self.params]

    def _layers(self, group: str) -> list[tuple[int, torch.Tensor, torch.Tensor]]:
        return [(i, self.params[2 * i], self.params[2 * i + 1]) for i in self.groups[group]]

    def forward_backward(
        self, xs: torch.Tensor, xm: torch.Tensor | None, y: torch.Tensor, sq_sum: torch.Tensor
    ) -> None:
        """One batch: fill ``self.grads`` with each seed's loss gradient; add each seed's summed
        squared error to ``sq_sum`` (K, 1, 1).

        xs (K, B, 5) sensors, xm (K, B, 2) motors (SM) or None (S), y (K, B, 5) next sensors.
        """
        params, grads = self.params, self.grads
        hs = _chain_forward(params, self.groups["sensor_encoder"], xs)  # [.., (K, B, 10)]
        z = hs[-1]
        if self.config.uses_motors:
            hm = _chain_forward(params, self.groups["motor_encoder"], xm)  # [.., (K, B, 5)]
            z = torch.cat([z, hm[-1]], dim=-1)  # (K, B, 15)
        hp = _chain_forward(params, self.groups["predictor"], z)  # [.., (K, B, 5)]
        diff = hp[-1].sub_(y)  # (K, B, 5)
        k, b = diff.shape[0], diff.shape[1]
        sq_sum.baddbmm_(diff.view(k, 1, -1), diff.view(k, -1, 1))  # += sum of squares
        dy = diff.mul_(2.0 / b)  # d/dpred of mean_B sum_5 (pred - y)^2
        dz = _chain_backward(params, grads, self.groups["predictor"], hp, dy, input_grad=True)
        zs = self.config.z_sensors
        if self.config.uses_motors:
            _chain_backward(params, grads, self.groups["motor_encoder"], hm, dz[..., zs:])
            dz = dz[..., :zs]
        _chain_backward(params, grads, self.groups["sensor_encoder"], hs, dz)

    @torch.no_grad()
    def predict(self, xs: torch.Tensor, xm: torch.Tensor | None = None) -> torch.Tensor:
        """Predictions (K, B, 5) of every seed for its own inputs (K, B, 5), (K, B, 2)."""
        z = _chain_forward(self.params, self.groups["sensor_encoder"], xs)[-1]
        if self.config.uses_motors:
            zm = _chain_forward(self.params, self.groups["motor_encoder"], xm)[-1]
            z = torch.cat([z, zm], dim=-1)
        return _chain_forward(self.params, self.groups["predictor"], z)[-1]


def linear_names(config: ModelConfig) -> list[str]:
    """Names of the ``nn.Linear`` modules of a model, in parameter order."""
    with torch.device("meta"):
        model = SensorimotorEncoder(config)
    return [n for n, m in model.named_modules() if isinstance(m, torch.nn.Linear)]


def _chain_forward(params, layers: list[int], h: torch.Tensor) -> list[torch.Tensor]:
    """Inputs of every layer of one chain, and its output: ReLU after all but the last."""
    hs = [h]
    last = layers[-1]
    for i in layers:
        h = torch.baddbmm(params[2 * i + 1], h, params[2 * i].mT)  # (K, B, out)
        if i != last:
            h = h.relu_()
        hs.append(h)
    return hs


def _chain_backward(params, grads, layers, hs, dy, input_grad: bool = False):
    """Gradients of one chain's weights into ``grads``; returns d/d(chain input) if asked."""
    for j in range(len(layers) - 1, -1, -1):
        i = layers[j]
        h = hs[j]  # (K, B, in): input of layer i
        torch.bmm(dy.mT, h, out=grads[2 * i])  # (K, out, in)
        torch.sum(dy, 1, keepdim=True, out=grads[2 * i + 1])  # (K, 1, out)
        if j:
            dy = RELU_GRAD(torch.bmm(dy, params[2 * i]), h, 0)  # (K, B, in), h = relu output
        elif input_grad:
            return torch.bmm(dy, params[2 * i])
    return None


class StackedAdam:
    """``train.FusedAdam`` on stacked tensors: the same fused kernel, so each seed gets exactly
    its own Adam. All seeds in a stack have taken the same number of steps (one step count)."""

    def __init__(self, net: StackedEncoders, lr: float = 1e-3, betas=(0.9, 0.999), eps=1e-8):
        self.net = net
        self.lr, self.betas, self.eps = lr, betas, eps
        self.exp_avg = [torch.zeros_like(p) for p in net.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in net.params]
        self.step_count = torch.zeros((), dtype=torch.float32, device=net.params[0].device)

    @torch.no_grad()
    def step(self) -> None:
        self.step_count.add_(1)
        params = self.net.params
        torch._fused_adam_(
            params,
            self.net.grads,
            self.exp_avg,
            self.exp_avg_sq,
            [],
            [self.step_count] * len(params),
            lr=self.lr,
            beta1=self.betas[0],
            beta2=self.betas[1],
            weight_decay=0.0,
            eps=self.eps,
            amsgrad=False,
            maximize=False,
        )

    def select(self, index: Sequence[int]) -> None:
        """Keep the Adam state of the seeds at ``index`` (call with ``net.select``)."""
        idx = torch.tensor(list(index), dtype=torch.long, device=self.step_count.device)
        self.exp_avg = [t.index_select(0, idx) for t in self.exp_avg]
        self.exp_avg_sq = [t.index_select(0, idx) for t in self.exp_avg_sq]

    def state_dict(self, k: int, shapes: list[torch.Size]) -> dict:
        """Seed ``k``'s state in ``train.FusedAdam``'s format (tensors shaped like ``shapes``)."""
        return {
            "exp_avg": [t[k].reshape(s).clone() for t, s in zip(self.exp_avg, shapes, strict=True)],
            "exp_avg_sq": [
                t[k].reshape(s).clone() for t, s in zip(self.exp_avg_sq, shapes, strict=True)
            ],
            "steps": [self.step_count.clone() for _ in shapes],
        }

    def load_state_dicts(self, states: Sequence[dict]) -> None:
        """Stack the ``train.FusedAdam`` states of every seed (all at the same step)."""
        steps = {float(st["steps"][0]) for st in states}
        if len(steps) != 1:
            raise ValueError(f"seeds at different Adam steps cannot share a stack: {steps}")
        for name in ("exp_avg", "exp_avg_sq"):
            for dst, *srcs in zip(getattr(self, name), *(st[name] for st in states), strict=True):
                dst.copy_(torch.stack([s.reshape(dst.shape[1:]) for s in srcs]))
        self.step_count.fill_(steps.pop())


def gather_epoch(
    s: torch.Tensor, m: torch.Tensor, seeds: Sequence[int], epoch: int
) -> torch.Tensor:
    """Each seed's data order of one epoch, as ``train.train_epoch_feedforward`` draws it:
    ``torch.randperm(n, generator=epoch_generator(seed, epoch))``; returns (K, n) indices."""
    from sensorimotor.train import epoch_generator

    n = len(s) - 1
    perms = [torch.randperm(n, generator=epoch_generator(seed, epoch)) for seed in seeds]
    return torch.stack(perms).to(s.device)  # (K, n)


def train_epoch_stacked(
    net: StackedEncoders,
    opt: StackedAdam,
    s: torch.Tensor,
    m: torch.Tensor,
    seeds: Sequence[int],
    epoch: int,
    batch: int,
) -> torch.Tensor:
    """One epoch of every seed in the stack over its own shuffled transitions.

    s (n + 1, 5), m (n + 1, 2) the train split; seed ``seeds[k]`` is row k of the stack.
    Returns each seed's mean training error (K,) (the paper's error, as the plain loop).
    """
    n = len(s) - 1
    if net.k != len(seeds):
        raise ValueError(f"{len(seeds)} seeds for a stack of {net.k}")
    perm = gather_epoch(s, m, seeds, epoch)  # (K, n)
    s0, m0, s1 = s[:-1], m[:-1], s[1:]
    sm = net.config.uses_motors
    sq_sum = torch.zeros(net.k, 1, 1, device=s.device)
    chunk = batch * CHUNK_BATCHES
    with torch.no_grad():
        for c in range(0, n, chunk):
            idx = perm[:, c : c + chunk]  # (K, c)
            xs_all, y_all = s0[idx], s1[idx]  # (K, c, 5), gathered once per chunk
            xm_all = m0[idx] if sm else None  # (K, c, 2)
            batches_s = xs_all.split(batch, dim=1)
            batches_y = y_all.split(batch, dim=1)
            batches_m = xm_all.split(batch, dim=1) if sm else [None] * len(batches_s)
            for xs, xm, y in zip(batches_s, batches_m, batches_y, strict=True):
                net.forward_backward(xs, xm, y, sq_sum)
                opt.step()
    return sq_sum.view(-1) / n
