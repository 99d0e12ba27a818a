"""The four encoders have the paper's layer sizes (section V.A) and the shared interface."""

import pytest
import torch
from torch import nn

from sensorimotor.learn.models import KINDS, ModelConfig, build_model, count_parameters


def linear(i: int, o: int) -> int:
    return i * o + o


def lstm(i: int, h: int) -> int:
    return 4 * h * (i + h) + 2 * 4 * h  # input and recurrent weights, two bias vectors


# Parameter counts derived by hand from DESIGN.md, section Learning.
FF_SENSOR = linear(5, 16) + linear(16, 32) + linear(32, 64) + linear(64, 10)
FF_MOTOR = linear(2, 16) + linear(16, 32) + linear(32, 64) + linear(64, 5)
REC_SENSOR = linear(5, 16) + lstm(16, 32) + 2 * lstm(32, 32) + linear(32, 10)
REC_MOTOR = linear(2, 16) + linear(16, 5)
EXPECTED = {
    "s": FF_SENSOR + linear(10, 128) + linear(128, 5),
    "sm": FF_SENSOR + FF_MOTOR + linear(15, 128) + linear(128, 5),
    "rec-s": REC_SENSOR + linear(10, 128) + linear(128, 5),
    "rec-sm": REC_SENSOR + REC_MOTOR + linear(15, 128) + linear(128, 5),
}


@pytest.mark.parametrize("kind", KINDS)
def test_parameter_counts_match_design(kind):
    assert count_parameters(build_model(kind)) == EXPECTED[kind]


def test_layer_sizes():
    sm = build_model("sm")
    sizes = [(m.in_features, m.out_features) for m in sm.sensor_encoder if isinstance(m, nn.Linear)]
    assert sizes == [(5, 16), (16, 32), (32, 64), (64, 10)]
    sizes = [(m.in_features, m.out_features) for m in sm.motor_encoder if isinstance(m, nn.Linear)]
    assert sizes == [(2, 16), (16, 32), (32, 64), (64, 5)]
    sizes = [(m.in_features, m.out_features) for m in sm.predictor if isinstance(m, nn.Linear)]
    assert sizes == [(15, 128), (128, 5)]
    rec = build_model("rec-sm")
    assert (rec.lstm.input_size, rec.lstm.hidden_size, rec.lstm.num_layers) == (16, 32, 3)
    # ReLU after every hidden layer, linear outputs
    assert isinstance(sm.sensor_encoder[-1], nn.Linear)
    assert sum(isinstance(m, nn.ReLU) for m in sm.sensor_encoder) == 3
    assert isinstance(sm.predictor[1], nn.ReLU)
    assert isinstance(sm.predictor[-1], nn.Linear)


@pytest.mark.parametrize("kind", KINDS)
def test_forward_shapes_and_encode(kind):
    model = build_model(kind, seed=0)
    s, m = torch.rand(3, 7, 5), torch.rand(3, 7, 2)
    pred, z, state = model(s, m)
    assert pred.shape == (3, 7, 5)
    assert z.shape == (3, 7, 10)
    z_alone, _ = model.encode(s)
    torch.testing.assert_close(z_alone, z)
    if ModelConfig(kind).recurrent:
        assert state[0].shape == (3, 3, 32)
    else:
        assert state is None


def test_motors_matter_only_for_sm_models():
    s, m = torch.rand(2, 4, 5), torch.rand(2, 4, 2)
    for kind in KINDS:
        model = build_model(kind, seed=1)
        a, _, _ = model(s, m)
        b, _, _ = model(s, m + 1)
        assert torch.equal(a, b) != ModelConfig(kind).uses_motors, kind
    with pytest.raises(ValueError, match="needs motor"):
        build_model("sm")(s)


def test_feedforward_steps_are_independent_recurrent_are_not():
    s = torch.rand(1, 6, 5)
    s2 = s.clone()
    s2[0, 0] += 1.0  # change only the first step
    for kind in KINDS:
        model = build_model(kind, seed=2)
        _, z1, _ = model(s, torch.zeros(1, 6, 2))
        _, z2, _ = model(s2, torch.zeros(1, 6, 2))
        later_changed = not torch.allclose(z1[0, 1:], z2[0, 1:])
        assert later_changed == ModelConfig(kind).recurrent, kind


def test_seed_fixes_initial_weights():
    a, b, c = build_model("rec-sm", 3), build_model("rec-sm", 3), build_model("rec-sm", 4)
    assert all(torch.equal(x, y) for x, y in zip(a.parameters(), b.parameters(), strict=True))
    assert not all(torch.equal(x, y) for x, y in zip(a.parameters(), c.parameters(), strict=True))


def test_unknown_kind_refused():
    with pytest.raises(ValueError, match="unknown model"):
        ModelConfig(kind="lstm")
