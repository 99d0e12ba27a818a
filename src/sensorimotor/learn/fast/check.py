"""The check that lets the stacked passes train a model: they compute what ``models.py``
computes (``computes_models_py``). ``engine.StackedEngine`` trains with them only where it holds;
elsewhere ``engine.AutogradEngine`` trains the ``nn.Module`` itself.
"""

from __future__ import annotations

import functools

import torch

from sensorimotor.learn.fast.stacked import StackedEncoders
from sensorimotor.learn.fast.stacked_lstm import forward_backward as recurrent_forward_backward
from sensorimotor.learn.fast.stacked_open_loop import forward_backward as open_loop_forward_backward
from sensorimotor.learn.models import ModelConfig, SensorimotorEncoder, build_model

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
def computes_models_py(model: ModelConfig | str) -> bool:
    """Whether the stack's hand-written passes compute what ``models.py`` computes for
    ``model`` (a kind: the paper's sizes; or any sizes and switches), checked once per
    process and model: its layers are those the passes know
    (``_known_layers``), and two steps (recurrent: two chunks, the state carried) give the
    loss and every gradient of autograd through the ``nn.Module``, to float32 rounding, on
    inputs ten times wider than the data's so that activations leave the range a fresh model
    sees. A model edited in ``models.py`` that fails this trains with autograd instead
    (``engine.AutogradEngine``). Tens of ms, and the first load of the numba kernels (about a second)."""
    module = build_model(model, seed=0)
    if not _known_layers(module):
        return False
    c = module.config
    try:
        net = StackedEncoders.from_models([module])
    except (KeyError, ValueError, RuntimeError):  # parameters the stack cannot lay out
        return False
    gen = torch.Generator().manual_seed(0)
    if c.motor_memory:
        return _open_loop_matches(module, net, gen)
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
        if not _close(net, module):
            return False
    return True


def _close(net: StackedEncoders, module: SensorimotorEncoder) -> bool:
    """Every gradient of the stack's one seed equals autograd's, to float32 rounding."""
    for g, p in zip(net.grads, module.parameters(), strict=True):
        grad = torch.zeros_like(p) if p.grad is None else p.grad
        if (g.reshape(p.shape) - grad).abs().max() > 1e-4 * grad.abs().max() + 1e-7:
            return False
    return True


def _open_loop_matches(module: SensorimotorEncoder, net: StackedEncoders, gen) -> bool:
    """``computes_models_py`` for a motor memory: two chunks of ``stacked_open_loop`` (the
    state and the last command carried, some targets weighted out) against autograd through
    ``encode`` and ``ahead`` with ``engine._open_loop_epoch``'s loss."""
    c = module.config
    t, b, ahead, every = 7, 3, 3, 2
    state = module_state = None
    for _ in range(2):
        xs = torch.rand(t, b, c.n_sensors, generator=gen) * 20 - 5  # (T, B, 5), time first
        xm = torch.rand(t + ahead - 1, b, c.n_motors, generator=gen) * 20 - 10
        y = torch.rand(t + ahead - 1, b, c.n_sensors, generator=gen)
        w = (torch.rand(ahead, -(-t // every), b, generator=gen) > 0.2).float()  # (A, T', B)
        try:
            state, sq, _ = open_loop_forward_backward(net, xs, xm, y, w, state, ahead, every)
        except (KeyError, ValueError, RuntimeError):
            return False
        module.zero_grad()
        z, module_state = module.encode(xs.transpose(0, 1), module_state, xm[:t].transpose(0, 1))
        module_state = tuple(h.detach() for h in module_state)  # truncated, as training
        pred = module.ahead(z, xm.transpose(0, 1), ahead, every)  # (A, B, T', 5)
        target = torch.stack([y[k : k + t : every].transpose(0, 1) for k in range(ahead)])
        err = (pred - target).square().sum(-1) * w.transpose(1, 2)  # (A, B, T')
        (err.sum() / w.sum().clamp(min=1)).backward()
        if not torch.allclose(sq, err.sum().detach().view(1), rtol=1e-4):
            return False
        if not _close(net, module):
            return False
    return True
