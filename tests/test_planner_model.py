"""The grasp DCNN (paper Sec. 4.1, Fig. 3) and its grid targets, against hand-counted answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from conftest import default_config
from torch import nn

from pipeline.grasping.types import GraspClass
from pipeline.planner import (
    EMPTY,
    GraspNet,
    NetworkConfig,
    conv_layers,
    count_flops,
    count_parameters,
    decode_output,
    decode_points,
    encode,
)
from pipeline.planner.decode import second_chance
from pipeline.planner.network import ConvBlock

R, L, B, NG = (int(c) for c in GraspClass)

# Width 1/32: every Darknet width divides exactly (32 → 1, 64 → 2, ..., 1024 → 32).
# (c_in, c_out, kernel, output side in pixels) of the 22 conv-BN-leaky layers, in forward order.
TINY_BLOCKS = [
    (1, 1, 3, 416),  # pool → 208
    (1, 2, 3, 208),  # pool → 104
    (2, 4, 3, 104),
    (4, 2, 1, 104),
    (2, 4, 3, 104),  # pool → 52
    (4, 8, 3, 52),
    (8, 4, 1, 52),
    (4, 8, 3, 52),  # pool → 26
    (8, 16, 3, 26),
    (16, 8, 1, 26),
    (8, 16, 3, 26),
    (16, 8, 1, 26),
    (8, 16, 3, 26),  # pool → 13
    (16, 32, 3, 13),
    (32, 16, 1, 13),
    (16, 32, 3, 13),
    (32, 16, 1, 13),
    (16, 32, 3, 13),
    (32, 32, 3, 13),
    (32, 32, 3, 13),  # head
    (16, 2, 1, 26),  # passthrough (stride 16)
    (32 + 4 * 2, 32, 3, 13),  # after space-to-depth concat
]
TINY_OUT = (32, 6, 1, 13)  # the linear output conv, with bias


def tiny_net() -> GraspNet:
    torch.manual_seed(0)
    return GraspNet(default_config(NetworkConfig, width=1 / 32))


def test_23_conv_layers():
    for width in (1 / 32, 0.25, 1.0):
        assert len(conv_layers(GraspNet(default_config(NetworkConfig, width=width)))) == 23


@pytest.mark.parametrize("width,batch", [(0.25, 2), (1.0, 1)])
def test_output_shape(width, batch):
    torch.manual_seed(0)
    net = GraspNet(default_config(NetworkConfig, width=width)).eval()
    with torch.no_grad():
        out = net(torch.rand(batch, 1, 416, 416))
    assert out.shape == (batch, 6, 13, 13)
    assert torch.isfinite(out).all()


def test_leaky_relu_after_every_conv_but_the_last():
    net = tiny_net()
    blocks = [m for m in net.modules() if isinstance(m, ConvBlock)]
    assert len(blocks) == 22
    for blk in blocks:
        assert isinstance(blk.bn, nn.BatchNorm2d) and blk.conv.bias is None
        assert isinstance(blk.act, nn.LeakyReLU) and blk.act.negative_slope == 0.1
    in_blocks = {id(b.conv) for b in blocks}
    last = conv_layers(net)[-1]
    assert id(last) not in in_blocks and last is net.out and last.bias is not None

    # Behaviour: 22 activations run, and the network's output is the last conv's raw output.
    calls, last_out = [], []
    for m in net.modules():
        if isinstance(m, nn.LeakyReLU):
            m.register_forward_hook(lambda *_: calls.append(1))
    last.register_forward_hook(lambda m, i, o: last_out.append(o))
    out = net(torch.randn(2, 1, 416, 416))
    assert len(calls) == 22
    assert torch.equal(out, last_out[0]) and (out < 0).any()  # linear: negatives pass through


def test_parameter_and_mac_counts_by_hand():
    net = tiny_net()
    c_in, c_out, k, side = TINY_OUT
    # conv + BN γ, β per block
    params = sum(kk * kk * ci * co + 2 * co for ci, co, kk, _ in TINY_BLOCKS)
    params += c_in * c_out + c_out  # 1×1 conv + bias
    assert count_parameters(net) == params == 50175
    macs = sum(kk * kk * ci * co * s * s for ci, co, kk, s in TINY_BLOCKS)
    macs += c_in * c_out * side**2
    assert count_flops(net) == macs == 15_758_912


def test_flops_match_measured_output_sizes():
    # count_flops uses each conv's tagged downsampling level; check it against a real forward.
    torch.manual_seed(0)
    net = GraspNet(default_config(NetworkConfig, width=0.25)).eval()
    measured = []
    for conv in conv_layers(net):
        conv.register_forward_hook(
            lambda m, i, o: measured.append(
                m.kernel_size[0] * m.kernel_size[1] * m.in_channels * o[0].numel()
            )
        )
    with torch.no_grad():
        net(torch.zeros(1, 1, 416, 416))
    assert len(measured) == 23 and sum(measured) == count_flops(net)


def test_output_bias_starts_at_cell_centre_and_class_prior():
    net = tiny_net()
    assert torch.equal(net.out.bias[:2], torch.zeros(2))  # sigmoid(0) = 0.5: cell centre
    assert torch.allclose(torch.sigmoid(net.out.bias[2:]), torch.full((4,), 0.01))


# ---------------------------------------------------------------- targets


def test_encode_single_point():
    t = encode(np.array([[16.0, 16.0]]), np.array([B]))
    assert t["obj"].sum() == 1 and t["obj"][0, 0]
    np.testing.assert_allclose(t["offset"][0, 0], [0.5, 0.5])
    assert t["cls"][0, 0] == B and t["lost"] == 0 and t["kept_index"][0, 0] == 0
    assert (t["cls"][~t["obj"]] == EMPTY).all() and (t["offset"][~t["obj"]] == 0).all()


def test_encode_row_is_v_column_is_u():
    # u = 100 → column 3 (96..128), offset 4/32; v = 40 → row 1, offset 8/32.
    t = encode(np.array([[100.0, 40.0]]), np.array([L]))
    assert t["obj"][1, 3] and t["cls"][1, 3] == L
    np.testing.assert_allclose(t["offset"][1, 3], [0.125, 0.25])


def test_encode_graspable_beats_ng_even_if_farther():
    # Cell (1, 1) spans 32..64, centre (48, 48). NG exactly at the centre, R at (60, 60).
    t = encode(np.array([[48.0, 48.0], [60.0, 60.0]]), np.array([NG, R]))
    assert t["lost"] == 1 and t["cls"][1, 1] == R and t["kept_index"][1, 1] == 1
    np.testing.assert_allclose(t["offset"][1, 1], [0.875, 0.875])  # 60/32 − 1


def test_encode_closest_to_cell_centre_among_graspable():
    # Both graspable in cell (1, 1): B at (35, 35) is 13√2 px from the centre, L at (50, 47)
    # √5 px: L wins. A third point in another cell is unaffected.
    uv = np.array([[35.0, 35.0], [50.0, 47.0], [200.0, 300.0]])
    t = encode(uv, np.array([B, L, NG]))
    assert t["lost"] == 1 and t["obj"].sum() == 2
    assert t["cls"][1, 1] == L
    np.testing.assert_allclose(t["offset"][1, 1], [50 / 32 - 1, 47 / 32 - 1])
    assert t["cls"][300 // 32, 200 // 32] == NG


def test_encode_last_cell_and_clamping():
    t = encode(np.array([[415.9, 0.0]]), np.array([B]))
    assert t["obj"][0, 12]
    np.testing.assert_allclose(t["offset"][0, 12], [415.9 / 32 - 12, 0.0], atol=1e-6)
    # A centre a fraction of a pixel past the border is clamped into the last cell, offset < 1.
    t = encode(np.array([[416.4, -0.3]]), np.array([R]))
    assert t["obj"][0, 12] and (t["offset"][0, 12] < 1).all() and t["offset"][0, 12, 1] == 0
    with pytest.raises(ValueError, match="outside"):
        encode(np.array([[500.0, 10.0]]), np.array([R]))


def test_encode_empty_and_decode_round_trip():
    t = encode(np.zeros((0, 2)), np.zeros(0, np.int8))
    assert not t["obj"].any() and t["lost"] == 0
    rng = np.random.default_rng(0)
    cells = rng.choice(169, size=20, replace=False)
    uv = np.stack([(cells % 13 + rng.random(20)) * 32, (cells // 13 + rng.random(20)) * 32], 1)
    classes = rng.integers(0, 4, 20)
    t = encode(uv, classes)
    back_uv, back_cls = decode_points(t["obj"], t["offset"], t["cls"])
    order = np.argsort(cells)  # decode returns row-major cell order
    np.testing.assert_allclose(back_uv, uv[order], atol=1e-4)
    np.testing.assert_array_equal(back_cls, classes[order])


def test_decode_output_positions_and_threshold():
    raw = torch.full((6, 13, 13), -10.0)
    raw[:2] = 0.0  # offsets 0.5
    raw[0, 2, 3], raw[1, 2, 3] = 0.0, math.log(3.0)  # cell row 2, col 3: offsets (0.5, 0.75)
    raw[2 + B, 2, 3] = 3.0  # p_B = sigmoid(3) = 0.952574
    preds = decode_output(raw, threshold=0.5)
    assert len(preds) == 1
    p = preds[0]
    assert p.grasp_class == GraspClass.B and p.probability == pytest.approx(0.952574, abs=1e-6)
    assert (p.u, p.v) == pytest.approx((3.5 * 32, 2.75 * 32))  # (112, 88)
    assert len(decode_output(raw, threshold=0.0)) == 169  # sigmoid(−10) = 4.5e-5 > 0


def fallback_raw() -> torch.Tensor:
    """Four cells (row, col) of a 13 x 13 output, offsets 0.5 (the cell centre), every other
    logit −10 (p = 4.5e-5):
    (2, 3): B = sigmoid(3) = 0.952574, kept by Eq. 3 at th 0.5;
    (5, 5): NG = sigmoid(2) = 0.880797 with L = sigmoid(0) = 0.5;
    (8, 1): R = sigmoid(−0.5) = 0.377541, the best class but below th;
    (10, 10): NG = 0.880797 with L = sigmoid(−2) = 0.119203."""
    raw = torch.full((6, 13, 13), -10.0)
    raw[:2] = 0.0
    raw[2 + B, 2, 3] = 3.0
    raw[2 + NG, 5, 5], raw[2 + L, 5, 5] = 2.0, 0.0
    raw[2 + R, 8, 1] = -0.5
    raw[2 + NG, 10, 10], raw[2 + L, 10, 10] = 2.0, -2.0
    return raw


def test_second_chance_by_hand():
    preds = decode_output(fallback_raw(), threshold=0.25)
    assert len(preds) == 4  # max class probability > 0.25 in all four cells
    out = second_chance(preds, threshold=0.5, fallback_threshold=0.25)
    # (2, 3) is Eq. 3's own; (10, 10)'s best class other than NG, L at 0.119, is below 0.25.
    assert [(p.u, p.v, p.grasp_class) for p in out] == [
        (5.5 * 32, 5.5 * 32, GraspClass.L),
        (1.5 * 32, 8.5 * 32, GraspClass.R),
    ]
    assert [p.probability for p in out] == pytest.approx([0.5, 0.377541], abs=1e-6)
    # the cell's own probabilities are kept (NG's included)
    assert out[0].class_probs[NG] == pytest.approx(0.880797, abs=1e-6)
    # a floor above R's 0.3775 leaves only the NG cell's L (0.5 > 0.4)
    assert [p.grasp_class for p in second_chance(preds, 0.5, 0.4)] == [GraspClass.L]


def test_plan_fallback_tier_follows_eq3_candidates(monkeypatch):
    """Level depth 0.6 m with a 0.5 m patch under the R cell: J_distance (Eq. 9, D_ground
    0.645 m) is 1 − 0.6/0.645 = 0.0698 at the B and L cells and 1 − 0.5/0.645 = 0.2248 at R.
    R outranks L within the second tier, but the tier follows Eq. 3's B whatever its J."""
    from pipeline.camera.geometry import Intrinsics
    from pipeline.planner.normalisation import Normalisation
    from pipeline.planner.planner import Planner
    from pipeline.planner.ranking import RankingConfig

    intr = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
    ranking = default_config(RankingConfig, d_ground=0.645, threshold=0.5)
    planner = Planner(tiny_net(), Normalisation(0.645, 1.0, 0.0), ranking)
    raw = fallback_raw()
    monkeypatch.setattr(planner, "predict", lambda depth: raw[None])
    depth = np.full((416, 416), 0.6, np.float32)
    depth[250:295, 25:72] = 0.5  # (u, v) = (48, 272) and its normal window
    plain = planner.plan(depth, intr)
    assert [(c.u, c.v, c.grasp_class) for c in plain] == [(112.0, 80.0, GraspClass.B)]
    both = planner.plan(depth, intr, fallback_threshold=0.25)
    assert [(c.u, c.v, c.grasp_class) for c in both] == [
        (112.0, 80.0, GraspClass.B),
        (48.0, 272.0, GraspClass.R),
        (176.0, 176.0, GraspClass.L),
    ]
    assert [c.score for c in both] == pytest.approx(
        [1 - 0.6 / 0.645, 1 - 0.5 / 0.645, 1 - 0.6 / 0.645], abs=1e-6
    )
    same = planner.plan(depth, intr, fallback_threshold=0.5)  # not below th: off
    assert [(c.u, c.v, c.grasp_class) for c in same] == [(112.0, 80.0, GraspClass.B)]
    # Only second-tier cells: Eq. 3 alone proposes nothing, the tier does.
    raw[2 + B, 2, 3] = -10.0
    assert planner.plan(depth, intr) == [] and planner.last_reason == "no_prediction"
    assert [c.grasp_class for c in planner.plan(depth, intr, fallback_threshold=0.25)] == [
        GraspClass.R,
        GraspClass.L,
    ] and planner.last_reason == ""
