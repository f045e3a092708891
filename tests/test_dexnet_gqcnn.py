"""The GQ-CNN's input crops and network shapes (``pipeline.dexnet.gqcnn``)."""

import numpy as np
import torch
from conftest import default_config

from pipeline.dexnet.gqcnn import GQCNN, CropConfig, GQCNNConfig, border_for_window, extract_crops

CFG = default_config(CropConfig, window_px=96, size=48, depth_scale=0.05, missing_value=1.0)  # 2:1


def _flat(h=200, w=200, z=0.5):
    return np.full((h, w), z, np.float32)


def test_crop_is_centred_on_the_candidate_and_of_the_right_size():
    depth = _flat()
    depth[80, 120] = 0.45  # a 5-cm bump at (u, v) = (120, 80)
    crops = extract_crops(
        depth, np.array([[120, 80]]), np.array([0.45]), np.array([[0.0, 0.0, 1.0]]), CFG
    )
    assert crops.shape == (1, 1, 48, 48) and crops.dtype == np.float32
    # 96 px → 48 px: the candidate is crop pixel (24, 24), relative height 0.
    assert crops[0, 0, 24, 24] == 0.0
    assert np.sum(crops[0, 0] < 0.5) == 1
    # Elsewhere: the plane, 5 cm below the candidate → (0.5 − 0.45) / 0.05 = 1.
    assert np.isclose(np.median(crops), 1.0)


def test_crop_rotates_the_approach_axis_onto_plus_u():
    depth = _flat()
    depth[100 + 20, 100] = 0.45  # a mark 20 px below (+v) the candidate at (100, 100)
    axis = np.array([[0.0, np.sin(0.3), np.cos(0.3)]])  # tilted towards +v: image angle 90°
    crops = extract_crops(depth, np.array([[100, 100]]), np.array([0.5]), axis, CFG)
    # After rotating +v onto +u and halving: the mark sits 10 px right of the centre (24, 24).
    v, u = np.unravel_index(np.argmin(crops[0, 0]), (48, 48))
    assert (u, v) == (34, 24)


def test_missing_depth_and_the_outside_read_the_missing_value():
    depth = _flat()
    depth[:, :10] = 0.0  # a column of holes at the left border
    crops = extract_crops(
        depth, np.array([[5, 100]]), np.array([0.5]), np.array([[0.0, 0.0, 1.0]]), CFG
    )
    # Left half of the crop: holes (u < 10) and outside the image (u < 0): missing value 1.0.
    assert np.all(crops[0, 0, :, :20] == 1.0)
    # Right of the holes: the plane at the candidate depth → 0.
    assert np.all(crops[0, 0, :, 30:] == 0.0)


def test_border_is_sqrt2_half_window():
    assert border_for_window(96) == 68  # ceil(√2 · 48) = ceil(67.88)


def test_network_maps_a_batch_to_one_logit_each():
    net = GQCNN(GQCNNConfig(crop_size=48, width=4, fc=16))
    out = net(torch.zeros(5, 1, 48, 48), torch.zeros(5, 2))
    assert out.shape == (5,)
