"""The grasp DCNN (paper Sec. 4.1, Fig. 3) and its grid targets, against hand-counted answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from conftest import default_config
from pipeline.labelling.types import GraspClass
from pipeline.planner import (
    EMPTY, GraspNet, NetworkConfig, conv_layers, count_flops, count_parameters, decode_output,
    decode_points, encode,
)
from pipeline.planner.network import ConvBlock

R, L, B, NG = (int(c) for c in GraspClass)

# Width 1/32: every Darknet width divides exactly (32 → 1, 64 → 2, ..., 1024 → 32).
# (c_in, c_out, kernel, output side in pixels) of the 22 conv-BN-leaky layers, in forward order.
TINY_BLOCKS = [
    (1, 1, 3, 416),                                                   # pool → 208
    (1, 2, 3, 208),                                                   # pool → 104
    (2, 4, 3, 104), (4, 2, 1, 104), (2, 4, 3, 104),                   # pool → 52
    (4, 8, 3, 52), (8, 4, 1, 52), (4, 8, 3, 52),                      # pool → 26
    (8, 16, 3, 26), (16, 8, 1, 26), (8, 16, 3, 26), (16, 8, 1, 26), (8, 16, 3, 26),  # pool → 13
    (16, 32, 3, 13), (32, 16, 1, 13), (16, 32, 3, 13), (32, 16, 1, 13), (16, 32, 3, 13),
    (32, 32, 3, 13), (32, 32, 3, 13),                                 # head
    (16, 2, 1, 26),                                                   # passthrough (stride 16)
    (32 + 4 * 2, 32, 3, 13),                                          # after space-to-depth concat
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
    macs += c_in * c_out * side ** 2
    assert count_flops(net) == macs == 15_758_912


def test_flops_match_measured_output_sizes():
    # count_flops uses each conv's tagged downsampling level; check it against a real forward.
    torch.manual_seed(0)
    net = GraspNet(default_config(NetworkConfig, width=0.25)).eval()
    measured = []
    for conv in conv_layers(net):
        conv.register_forward_hook(lambda m, i, o: measured.append(
            m.kernel_size[0] * m.kernel_size[1] * m.in_channels * o[0].numel()))
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
