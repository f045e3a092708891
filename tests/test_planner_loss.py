"""The DCNN loss (paper Eqs. 4–6) on 1×1 and 2×2 grids, against values worked out by hand.

With all logits 0, every p = sigmoid(0) = 0.5 and ln 0.5 = −0.693147:
  a positive class term is −α (1 − p)^γ ln p      = 0.25 · 0.25 · 0.693147 = 0.0433217
  a negative class term is −(1 − α) p^γ ln(1 − p) = 0.75 · 0.25 · 0.693147 = 0.1299651
and the predicted offset is sigmoid(0) = 0.5 of a cell.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from conftest import default_config

from pipeline.grasping.types import GraspClass
from pipeline.planner import (
    GraspNet,
    LossConfig,
    NetworkConfig,
    encode,
    focal_terms,
    grasp_loss,
    stack_targets,
)

R, L, B, NG = (int(c) for c in GraspClass)
POS0 = 0.25 * 0.25 * math.log(2)  # 0.0433217
NEG0 = 0.75 * 0.25 * math.log(2)  # 0.1299651
LOSS = default_config(LossConfig)  # train.alpha = 0.25, gamma = 2, both lambdas 1


def targets(grid: int, points: dict) -> dict[str, torch.Tensor]:
    """One image's targets from {(row, col): (class, (off_u, off_v))}, batch of 1."""
    obj = torch.zeros(1, grid, grid, dtype=torch.bool)
    offset = torch.zeros(1, grid, grid, 2)
    cls = torch.full((1, grid, grid), -1, dtype=torch.long)
    for (r, c), (k, off) in points.items():
        obj[0, r, c], cls[0, r, c], offset[0, r, c] = True, k, torch.tensor(off)
    return {"obj": obj, "offset": offset, "cls": cls}


def cat(*ts):
    return {k: torch.cat([t[k] for t in ts]) for k in ts[0]}


def test_focal_terms_by_hand():
    x = torch.tensor([0.0, 0.0, math.log(3.0), math.log(3.0)])  # p = 0.5, 0.5, 0.75, 0.75
    t = torch.tensor([1.0, 0.0, 1.0, 0.0])
    expected = [
        POS0,  # 0.0433217
        NEG0,  # 0.1299651
        0.25 * 0.25**2 * -math.log(0.75),  # −α (0.25)² ln 0.75 = 0.0044950
        0.75 * 0.75**2 * -math.log(0.25),  # −(1 − α) (0.75)² ln 0.25 = 0.5848430
    ]
    np.testing.assert_allclose(focal_terms(x, t, 0.25, 2.0).numpy(), expected, rtol=1e-6)


def test_focal_terms_stable_for_large_logits():
    x = torch.tensor([100.0, -100.0, 100.0, -100.0], requires_grad=True)
    t = torch.tensor([0.0, 1.0, 1.0, 0.0])
    v = focal_terms(x, t, 0.25, 2.0)
    # Confidently wrong: −ln(1 − p) = −ln sigmoid(−100) = 100, weight 0.75 · 1;
    # a missed positive: 0.25 · 100.
    np.testing.assert_allclose(v.detach().numpy(), [75.0, 25.0, 0.0, 0.0], atol=1e-5)
    v.sum().backward()
    assert torch.isfinite(x.grad).all()


def test_one_point_on_a_1x1_grid():
    raw = torch.zeros(1, 6, 1, 1)
    loss = grasp_loss(raw, targets(1, {(0, 0): (B, (0.25, 0.75))}), LOSS)
    # L_coord = (0.5 − 0.25)² + (0.5 − 0.75)² = 0.125; L_class = 0.0433217 + 3 · 0.1299651.
    assert loss["coord"].item() == pytest.approx(0.125, abs=1e-6)
    assert loss["class"].item() == pytest.approx(0.4332170, abs=1e-6)
    assert loss["total"].item() == pytest.approx(0.5582170, abs=1e-6)


def test_empty_cells_are_all_negative_2x2():
    raw = torch.zeros(1, 6, 2, 2)
    loss = grasp_loss(raw, targets(2, {(1, 0): (R, (0.25, 0.75))}), LOSS)
    # The GT cell as above plus 3 empty cells × 4 negatives: 0.4332170 + 12 · 0.1299651.
    assert loss["class"].item() == pytest.approx(1.9927981, abs=1e-6)
    assert loss["coord"].item() == pytest.approx(0.125, abs=1e-6)  # empty cells add no L_coord
    assert loss["total"].item() == pytest.approx(2.1177981, abs=1e-6)
    assert loss["num_points"].tolist() == [1]


def test_normalised_by_the_number_of_points():
    raw = torch.zeros(1, 6, 2, 2)
    raw[0, 0, 0, 1] = math.log(3.0)  # cell (0, 1): offset_u = 0.75
    t = targets(2, {(0, 0): (R, (0.25, 0.75)), (0, 1): (NG, (0.75, 0.5))})
    loss = grasp_loss(raw, t, LOSS)
    # B = 2. L_coord = (0.125 + 0) / 2; L_class = (2 · 0.4332170 + 2 cells · 4 · 0.1299651) / 2.
    assert loss["coord"].item() == pytest.approx(0.0625, abs=1e-6)
    assert loss["class"].item() == pytest.approx(0.9530774, abs=1e-6)


def test_no_points_guard_and_batch_mean():
    raw = torch.zeros(2, 6, 2, 2, requires_grad=True)
    empty = targets(2, {})
    loss = grasp_loss(raw[:1], empty, LOSS)
    # B = 0 → divided by 1: 16 negatives · 0.1299651 = 3 ln 2 = 2.0794415; no L_coord.
    assert loss["class"].item() == pytest.approx(3 * math.log(2), abs=1e-6)
    assert loss["coord"].item() == 0.0 and loss["num_points"].tolist() == [0]
    # Batch = mean of per-image losses: (2.1177981 + 2.0794415) / 2.
    batch = grasp_loss(raw, cat(targets(2, {(1, 0): (R, (0.25, 0.75))}), empty), LOSS)
    assert batch["total"].item() == pytest.approx(2.0986198, abs=1e-6)
    batch["total"].backward()
    assert torch.isfinite(raw.grad).all() and raw.grad.abs().sum() > 0


def test_loss_with_network_and_encoded_targets_trains():
    torch.manual_seed(0)
    net = GraspNet(default_config(NetworkConfig, width=1 / 32))
    depth = torch.rand(2, 1, 416, 416)
    t = stack_targets(
        [
            encode(np.array([[16.0, 16.0], [200.0, 100.0], [300.0, 380.0]]), np.array([B, L, NG])),
            encode(np.zeros((0, 2)), np.zeros(0)),
        ]
    )
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    history = []
    for _ in range(8):
        loss = grasp_loss(net(depth), t, LOSS)
        assert all(torch.isfinite(v).all() for v in loss.values())
        opt.zero_grad()
        loss["total"].backward()
        assert all(torch.isfinite(p.grad).all() for p in net.parameters() if p.grad is not None)
        opt.step()
        history.append(loss["total"].item())
    assert history[-1] < history[0]


def test_grid_mismatch_is_an_error():
    with pytest.raises(ValueError, match="grid"):
        grasp_loss(torch.zeros(1, 6, 13, 13), targets(2, {}), LOSS)
