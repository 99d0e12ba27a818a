"""The CUDA path: the same training code with the data resident on the GPU (skipped without one).

CI has no GPU; these run where one is lent (``python -m pytest tests/learn/test_cuda.py``).
"""

from __future__ import annotations

import warnings

import pytest
import torch

from sensorimotor.learn.batches import epoch_generator
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import train_epoch_feedforward, train_epoch_recurrent
from sensorimotor.learn.evaluate import load_run, model_error, split_tensors
from sensorimotor.learn.fast import cuda_graphs
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.stacked import StackedEncoders, train_epoch_stacked
from sensorimotor.learn.models import build_model
from sensorimotor.learn.train import resolve_device, train_seeds
from sensorimotor.sim.database import load_database

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


def _split(db_path, device, steps):
    s, m = split_tensors(load_database(db_path), "train", device)
    return s[: steps + 1], m[: steps + 1]


def _relative(a: list[torch.Tensor], b: list[torch.Tensor]) -> float:
    """Largest difference of a tensor of ``a`` from its twin in ``b``, over b's largest entry."""
    pairs = zip(a, b, strict=True)
    return max(float((x.cpu() - y.cpu()).abs().max() / y.abs().max()) for x, y in pairs)


@pytest.mark.parametrize("kind", ["s", "sm"])
def test_stacked_epoch_on_cuda_equals_the_cpu_one(kind, square_db_path):
    """Three seeds, 100 batches: the same weights on the GPU as on the CPU, to float32 rounding
    (no TF32: matmul precision stays 'highest')."""
    seeds = [0, 1, 2]
    nets = {}
    for device in ("cpu", "cuda"):
        s, m = _split(square_db_path, device, 64 * 100)
        models = [build_model(kind, seed=sd).to(device) for sd in seeds]
        nets[device] = StackedEncoders.from_models(models)
        errors = train_epoch_stacked(nets[device], s, m, seeds, 0, 64)
        assert errors.device.type == device
    assert _relative(nets["cuda"].params, nets["cpu"].params) < 1e-4
    assert _relative(nets["cuda"].exp_avg_sq, nets["cpu"].exp_avg_sq) < 1e-3


def _syncs(fn) -> int:
    """How many host synchronisations ``fn()`` makes (torch's sync debug mode, 'warn')."""
    torch.cuda.synchronize()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        torch.cuda.set_sync_debug_mode("warn")  # itself warns: a prototype
        try:
            fn()
        finally:
            torch.cuda.set_sync_debug_mode("default")
    return sum("called a synchronizing" in str(w.message) for w in caught)


def test_no_host_synchronisation_per_step(square_db_path):
    """An epoch of 40 batches synchronises with the host no more often than one of 10: the
    per-step work stays on the GPU (the few syncs left are once per epoch)."""
    s, m = _split(square_db_path, "cuda", 64 * 40)
    short = (s[: 64 * 10 + 1], m[: 64 * 10 + 1])
    net = StackedEncoders.from_models([build_model("sm", seed=sd).cuda() for sd in (0, 1)])
    model = build_model("sm", seed=0).cuda()
    opt = FusedAdam(model.parameters())
    rec = build_model("rec-sm", seed=0).cuda()
    rec_opt = FusedAdam(rec.parameters())

    def stacked(s, m):
        train_epoch_stacked(net, s, m, [0, 1], 0, 64)

    def plain(s, m):
        train_epoch_feedforward(model, opt, s, m, 64, epoch_generator(0, 0))

    def recurrent(s, m):  # horizon 5: 2 and 8 chunks
        train_epoch_recurrent(rec, rec_opt, s, m, 64, 5)

    for epoch in (stacked, plain, recurrent):
        epoch(*short)  # CUDA graphs are captured here, once
        few, many = _syncs(lambda e=epoch: e(*short)), _syncs(lambda e=epoch: e(s, m))
        assert 0 < few == many, (epoch.__name__, few, many)  # 0: the count would prove nothing


def test_recurrent_gradients_on_cuda_equal_the_cpu_ones(square_db_path):
    """cuDNN's LSTM, in float32 as training sets it (``resolve_device``: no TF32), gives the
    CPU's gradients for a truncated-BPTT chunk carried from a previous one."""
    resolve_device("cuda")
    grads = {}
    for device in ("cpu", "cuda"):
        s, m = _split(square_db_path, device, 64 * 40)
        x, xm, y = (t[: 64 * 40].view(64, 40, -1) for t in (s, m, s[1:]))  # 64 streams
        model = build_model("rec-sm", seed=0).to(device)
        _, _, state = model(x[:, :20], xm[:, :20])
        pred, _, _ = model(x[:, 20:], xm[:, 20:], tuple(t.detach() for t in state))
        ((pred - y[:, 20:]) ** 2).sum(-1).mean().backward()
        grads[device] = [p.grad for p in model.parameters()]
    assert _relative(grads["cuda"], grads["cpu"]) < 1e-4


@pytest.mark.parametrize("kind", ["sm", "rec-s"])
def test_runs_trained_on_cuda_evaluate_on_the_cpu(kind, square_db_path, tmp_path):
    """``train_seeds`` on CUDA (stacked for SM, one seed after another for Rec-S) writes run
    folders that load on the CPU, with the validation error their record says."""
    config = TrainConfig(model=kind, device="cuda", max_epochs=2, patience=5)
    results = train_seeds(square_db_path, tmp_path, config, [0, 1])
    assert [r.epochs for r in results] == [2, 2]
    vs, vm = split_tensors(load_database(square_db_path), "val", "cpu")
    for result, seed in zip(results, (0, 1), strict=True):
        run = load_run(tmp_path / f"square__{kind}__s{seed}")
        assert next(run.model.parameters()).device.type == "cpu"
        assert model_error(run.model, vs, vm) == pytest.approx(result.best_val_error, rel=1e-4)


def _two_epochs(kind, s, m, graphs: bool, monkeypatch):
    """Weights and Adam moments after two epochs of 3 seeds of ``kind`` on CUDA, with or
    without CUDA graphs, and each epoch's training errors."""
    monkeypatch.setattr(cuda_graphs, "ENABLED", graphs)
    seeds = [0, 1, 2]
    errors = []
    if kind.startswith("rec"):
        model = build_model(kind, seed=0).cuda()
        opt = FusedAdam(model.parameters())
        for _ in range(2):
            errors.append(train_epoch_recurrent(model, opt, s, m, 64, 20))
        return [p.detach() for p in model.parameters()] + opt.exp_avg_sq, errors
    net = StackedEncoders.from_models([build_model(kind, seed=sd).cuda() for sd in seeds])
    for epoch in range(2):
        errors.append(train_epoch_stacked(net, s, m, seeds, epoch, 64).tolist())
    return net.params + net.exp_avg_sq, errors


@pytest.mark.parametrize("kind", ["sm", "rec-sm"])
def test_cuda_graphs_train_as_the_eager_loop(kind, square_db_path, monkeypatch):
    """Replayed graphs run the eager loop's kernels: the same weights, moments and errors, bit
    for bit, over epochs that end with what the graphs leave to the eager loop (a partial
    group of batches; stream ends padded in the last chunks)."""
    n = 64 * 32 * 3 + 64 * 5 + 17 if kind == "sm" else 64 * 20 * 7 + 30
    s, m = _split(square_db_path, "cuda", n)
    graphed, errors_graphed = _two_epochs(kind, s, m, True, monkeypatch)
    eager, errors_eager = _two_epochs(kind, s, m, False, monkeypatch)
    assert errors_graphed == errors_eager
    for a, b in zip(graphed, eager, strict=True):
        assert torch.equal(a, b)
