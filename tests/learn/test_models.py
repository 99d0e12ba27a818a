"""The four encoders have the paper's layer sizes (section V.A), Rec-SMA its own, and all the
shared interface."""

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
    # the memory reads 16 + 2 (the last command); the transition is 15 -> 64 -> 10
    "rec-sma": REC_SENSOR
    + 4 * 32 * 2
    + REC_MOTOR
    + linear(15, 128)
    + linear(128, 5)
    + linear(15, 64)
    + linear(64, 10),
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
    z_alone, _ = model.encode(s, motors=m)
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


def test_motor_memory_reads_the_last_command_and_carries_it_across_chunks():
    model = build_model("rec-sma", seed=0)
    s, m = torch.rand(2, 9, 5), torch.rand(2, 9, 2)
    _, z, _ = model(s, m)
    m2 = m.clone()
    m2[:, 4] += 1.0  # the command at step 4 reaches the memory at step 5, not before
    _, z2, _ = model(s, m2)
    assert torch.equal(z[:, :5], z2[:, :5])
    assert not torch.allclose(z[:, 5:], z2[:, 5:])
    _, za, state = model(s[:, :4], m[:, :4])  # chunked: the state carries m_3 to step 4
    _, zb, _ = model(s[:, 4:], m[:, 4:], state)
    torch.testing.assert_close(torch.cat([za, zb], 1), z)


def test_the_ablation_without_motors_in_memory_ignores_them():
    model = build_model(ModelConfig("rec-sma", memory_motors=False), seed=0)
    s, m = torch.rand(2, 6, 5), torch.rand(2, 6, 2)
    assert torch.equal(model(s, m)[1], model(s, m + 1)[1])  # z_s: blind to the commands
    with pytest.raises(ValueError, match="does not read motors"):
        ModelConfig("rec-sm", memory_motors=True)


def test_open_loop_starts_with_forwards_prediction_and_begins_still():
    model = build_model("rec-sma", seed=0)
    s, m = torch.rand(2, 10, 5), torch.rand(2, 10, 2)
    pred, z, _ = model(s, m)
    ahead = model.ahead(z[:, :7], m, 4)  # (K, B, T, 5) from m_t .. m_{t+3}
    assert ahead.shape == (4, 2, 7, 5)
    torch.testing.assert_close(ahead[0], pred[:, :7])
    # a fresh transition leaves the belief where it is: step k reads z_t with m_{t+k-1}
    z_m = model.motor_encoder(m)
    still = model.predictor(torch.cat([z[:, :7], z_m[:, 3:10]], -1))
    torch.testing.assert_close(ahead[3], still)
    with pytest.raises(ValueError, match="no open-loop"):
        build_model("rec-sm").ahead(z, m, 2)


def test_seed_fixes_initial_weights():
    a, b, c = build_model("rec-sm", 3), build_model("rec-sm", 3), build_model("rec-sm", 4)
    assert all(torch.equal(x, y) for x, y in zip(a.parameters(), b.parameters(), strict=True))
    assert not all(torch.equal(x, y) for x, y in zip(a.parameters(), c.parameters(), strict=True))


def test_unknown_kind_refused():
    with pytest.raises(ValueError, match="unknown model"):
        ModelConfig(kind="lstm")
