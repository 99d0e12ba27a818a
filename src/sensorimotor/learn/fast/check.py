"""The check that lets the stacked passes train a model: they compute what ``models.py``
computes (``computes_models_py``). ``engine.StackedEngine`` trains with them only where it holds;
elsewhere ``engine.AutogradEngine`` trains the ``nn.Module`` itself.
"""

from __future__ import annotations

import functools

import torch

from sensorimotor.learn.fast.stacked import StackedEncoders
from sensorimotor.learn.fast.stacked_lstm import forward_backward as recurrent_forward_backward
from sensorimotor.learn.models import SensorimotorEncoder, build_model

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
