"""The DCNN's training loss (paper Eqs. 4–6).

    L = λ_coord L_coord + λ_class L_class                                         (4)
    L_coord = 1/B Σ_j 1^GP_j [(g^u_j − ĝ^u_j)² + (g^v_j − ĝ^v_j)²]                 (5)
    L_class = 1/B Σ_j Σ_c  −α (1 − p)^γ log p          if the target p̂_j(c) = 1
                           −(1 − α) p^γ log(1 − p)     otherwise                  (6)

Choices the paper leaves open:

* **Units of L_coord**: offsets in cell units (fractions of a 32-pixel cell), the predicted
  offset being sigmoid(raw) ∈ (0, 1) (``network.split_output``); so an error of one cell side
  along u costs 1.
* **p_j(c)** is a per-class sigmoid of the class logit (Eq. 6 is RetinaNet's sigmoid focal
  loss), so the four probabilities need not sum to 1.
* **Cells without a ground-truth point** get an all-zero class target: every class is a
  negative there and is pushed to low probability. This is what makes Eq. 3's test
  "max_c p_j(c) > th" a detection test: a cell outputs a point only if some class is confident.
  Their L_coord term is zero (1^GP = 0).
* **B** is the number of ground-truth points of the image after the one-per-cell rule (=
  cells with 1^GP = 1). An image with B = 0 is normalised by 1 instead (RetinaNet's
  max(1, num_positives)): its loss is then the sum of the negative terms of all cells, so empty
  images still teach the network to output nothing.
* **Batches**: the loss of a batch is the mean over images of the per-image losses.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from pipeline.config.build import from_section
from pipeline.planner.network import split_output


@dataclass
class LossConfig:
    """Focal-loss parameters and term weights (Eqs. 4–6): ``alpha``, ``gamma``, ``lambda_coord``
    and ``lambda_class`` of the ``train`` section, built by :func:`loss_config`."""

    alpha: float  # paper Sec. 4.1
    gamma: float
    lambda_coord: float
    lambda_class: float


def loss_config(cfg) -> LossConfig:
    """The loss of a composed config (``cfg.train``)."""
    return from_section(LossConfig, cfg.train)


def focal_terms(
    logits: torch.Tensor, targets: torch.Tensor, alpha: float, gamma: float
) -> torch.Tensor:
    """Eq. 6's summand per element, from logits x (any shape) and 0/1 targets (same shape).

    log p = logsigmoid(x) and log(1 − p) = logsigmoid(−x) stay finite for any x, and
    1 − p = sigmoid(−x) loses no precision when p → 1.
    """
    p = torch.sigmoid(logits)
    positive = -alpha * torch.sigmoid(-logits).pow(gamma) * F.logsigmoid(logits)
    negative = -(1 - alpha) * p.pow(gamma) * F.logsigmoid(-logits)
    return torch.where(targets > 0.5, positive, negative)


def grasp_loss(
    raw: torch.Tensor, targets: dict[str, torch.Tensor], cfg: LossConfig
) -> dict[str, torch.Tensor]:
    """Eqs. 4–6 for a batch.

    Args:
        raw: (B, 2 + C, N, N) network output (offset logits, then class logits).
        targets: ``targets.stack_targets`` output: ``obj`` (B, N, N) bool, ``offset``
            (B, N, N, 2) float in [0, 1) cell units, ``cls`` (B, N, N) int64 (−1 where empty).
        cfg: weights and focal parameters.

    Returns:
        dict of scalar tensors ``total``, ``coord``, ``class`` (batch means of per-image values)
        and ``num_points`` (B,) the per-image B.
    """
    offset_pred, class_logits = split_output(raw)  # (B, N, N, 2) in (0, 1), (B, N, N, C)
    obj = targets["obj"].to(raw.device).bool()  # (B, N, N)
    offset_true = targets["offset"].to(raw.device, raw.dtype)  # (B, N, N, 2)
    cls = targets["cls"].to(raw.device).long()  # (B, N, N)
    if obj.shape != class_logits.shape[:3]:
        raise ValueError(
            f"targets are for grids {tuple(obj.shape)}, the network output is "
            f"{tuple(class_logits.shape[:3])}; encode with the network's grid"
        )

    num_points = obj.flatten(1).sum(1)  # (B,)
    norm = num_points.clamp(min=1).to(raw.dtype)  # (B,)

    sq_err = ((offset_pred - offset_true) ** 2).sum(-1)  # (B, N, N)
    coord = (sq_err * obj).flatten(1).sum(1) / norm  # (B,)

    num_classes = class_logits.shape[-1]
    one_hot = F.one_hot(cls.clamp(min=0), num_classes).to(raw.dtype)  # (B, N, N, C)
    one_hot = one_hot * obj.unsqueeze(-1)  # all-zero target in empty cells
    class_ = focal_terms(class_logits, one_hot, cfg.alpha, cfg.gamma).flatten(1).sum(1) / norm

    total = cfg.lambda_coord * coord + cfg.lambda_class * class_  # (B,)
    return {
        "total": total.mean(),
        "coord": coord.mean(),
        "class": class_.mean(),
        "num_points": num_points,
    }
