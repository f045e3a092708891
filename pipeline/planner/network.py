"""The grasp-point DCNN (paper Sec. 4.1, Fig. 3): a YOLOv2-style single-scale grid detector.

"Darknet-23" in the paper is read as the YOLOv2 detector built on Darknet-19, which has exactly
23 convolutional layers:

* Darknet-19 without its classifier: 18 convs (3×3 / 1×1 alternating) and 5 max-pools,
  416 → 13 pixels per side (stride 32);
* the detection head: two 3×3 convs; a 1×1 "passthrough" conv on the 26×26 stride-16 features,
  folded to 13×13 by space-to-depth and concatenated; one 3×3 conv; and the output conv.

Every conv except the last is conv (no bias) → BatchNorm → LeakyReLU(0.1); the last
("conv. layer*" in Fig. 3) is a linear 1×1 conv with bias. Channel widths are Darknet-19's
multiplied by ``width`` (1.0 = the paper's full-size net, 0.25 trains on a laptop CPU).

Input: (B, 1, 416, 416) depth image (float; scaling is the caller's choice).
Output: (B, 6, 13, 13) raw values per grid cell, row = v cell, column = u cell:

* channels 0, 1: the grasp point's position inside the cell along u and v, as *logits*. The
  network itself applies no sigmoid; ``split_output`` (used by both the loss and the decoder)
  maps them to (0, 1) cell units with a sigmoid, so training and inference cannot disagree.
* channels 2..5: class logits in ``GraspClass`` order (R, L, B, NG); probabilities are
  per-class sigmoids (the focal loss of Eq. 6 is the binary/sigmoid form).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from pipeline.config.build import from_section

NUM_COORDS = 2  # (u, v) offset inside a cell

# Darknet-19 without its classifier: (out_channels, kernel) per conv, "M" = 2×2 max-pool.
# Split where the passthrough taps the stride-16 features.
DARKNET19_TO_STRIDE16 = [
    (32, 3),
    "M",
    (64, 3),
    "M",
    (128, 3),
    (64, 1),
    (128, 3),
    "M",
    (256, 3),
    (128, 1),
    (256, 3),
    "M",
    (512, 3),
    (256, 1),
    (512, 3),
    (256, 1),
    (512, 3),
]
DARKNET19_TO_STRIDE32 = ["M", (1024, 3), (512, 1), (1024, 3), (512, 1), (1024, 3)]
HEAD_CHANNELS = 1024
PASSTHROUGH_CHANNELS = 64
# Initial class probability of the output layer (RetinaNet, Lin et al. 2017, Sec. 4.1): with
# ~169 cells of which ~10 hold a point, starting at p = 0.5 would let the all-negative cells
# dominate the first steps of the focal loss.
CLASS_PRIOR = 0.01


@dataclass
class NetworkConfig:
    """The DCNN's shape: the ``model`` group (``conf/model/``, the width set by the experiment),
    built by :func:`network_config`."""

    width: float  # channel multiplier on Darknet-19 widths
    grid: int  # N, cells per side (paper: 13)
    input_size: int  # pixels per side
    num_classes: int  # R, L, B, NG
    leaky_slope: float

    def __post_init__(self):
        if self.input_size != self.grid * 32:
            raise ValueError(
                f"input_size {self.input_size} must be 32 × grid ({self.grid}) "
                f"= {32 * self.grid}: the backbone downsamples by 32"
            )
        if self.width <= 0:
            raise ValueError(f"width must be > 0, got {self.width}")


def network_config(cfg) -> NetworkConfig:
    """The network of a composed config's ``model`` group."""
    return from_section(NetworkConfig, cfg.model)


def scaled(channels: int, width: float) -> int:
    """Darknet width ``channels`` scaled by ``width``, at least 1."""
    return max(1, int(round(channels * width)))


def _conv(c_in: int, c_out: int, kernel: int, level: int, bias: bool) -> nn.Conv2d:
    """A stride-1 "same" conv tagged with ``level``, the number of 2× downsamplings before it
    (its output is (S / 2^level)² pixels; ``count_flops`` reads it)."""
    conv = nn.Conv2d(c_in, c_out, kernel, padding=kernel // 2, bias=bias)
    conv.level = level
    return conv


class ConvBlock(nn.Module):
    """conv (no bias: BatchNorm has one) → BatchNorm → LeakyReLU."""

    def __init__(self, c_in: int, c_out: int, kernel: int, slope: float, level: int):
        super().__init__()
        self.conv = _conv(c_in, c_out, kernel, level, bias=False)
        self.bn = nn.BatchNorm2d(c_out)
        self.act = nn.LeakyReLU(slope, inplace=True)

    def forward(self, x):  # (B, c_in, H, W) → (B, c_out, H, W)
        return self.act(self.bn(self.conv(x)))


class MaxPool2x2(nn.MaxPool2d):
    """2 × 2 max-pool, stride 2: ``nn.MaxPool2d(2, 2)``. Without autograd on the CPU (planning,
    evaluation), the elementwise maximum of the image's rows taken in pairs, then of its columns:
    the same values (a maximum is exact, and NaN propagates through both), without the index of
    each maximum that ``max_pool2d`` also finds for a backward pass and the branch per element
    that finding it takes, which made pooling a sizeable part of a narrow network's forward pass
    on one thread (``make bench ARGS="--only planners"``). With autograd,
    ``max_pool2d``: its gradient goes to one element of a tied window, where
    ``torch.maximum``'s would be split between them."""

    def __init__(self) -> None:
        super().__init__(2, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled() or x.device.type != "cpu" or x.shape[-1] % 2 or x.shape[-2] % 2:
            return super().forward(x)
        rows = torch.maximum(x[..., 0::2, :], x[..., 1::2, :])
        return torch.maximum(rows[..., 0::2], rows[..., 1::2])


class GraspNet(nn.Module):
    """Depth image (B, 1, S, S) → raw grid output (B, 2 + num_classes, S/32, S/32)."""

    def __init__(self, cfg: NetworkConfig):
        super().__init__()
        self.cfg = cfg
        w, slope = cfg.width, cfg.leaky_slope
        self.out_channels = NUM_COORDS + cfg.num_classes

        self.stage16, c16, level = self._stage(DARKNET19_TO_STRIDE16, 1, 0)  # stride 16
        self.stage32, c, _ = self._stage(DARKNET19_TO_STRIDE32, c16, level)  # stride 32

        head = scaled(HEAD_CHANNELS, w)
        self.head = nn.Sequential(
            ConvBlock(c, head, 3, slope, 5), ConvBlock(head, head, 3, slope, 5)
        )
        self.passthrough = ConvBlock(c16, scaled(PASSTHROUGH_CHANNELS, w), 1, slope, 4)
        c_cat = head + 4 * scaled(PASSTHROUGH_CHANNELS, w)  # space-to-depth ×4 channels
        self.fuse = ConvBlock(c_cat, head, 3, slope, 5)
        self.out = _conv(head, self.out_channels, 1, 5, bias=True)  # linear: "conv. layer*"
        with torch.no_grad():  # offsets start at the cell centre, classes at CLASS_PRIOR
            self.out.bias.zero_()
            self.out.bias[NUM_COORDS:] = -math.log((1 - CLASS_PRIOR) / CLASS_PRIOR)

    def _stage(self, spec, c: int, level: int) -> tuple[nn.Sequential, int, int]:
        layers = []
        for item in spec:
            if item == "M":
                layers.append(MaxPool2x2())
                level += 1
            else:
                c_out, kernel = item
                layers.append(
                    ConvBlock(c, scaled(c_out, self.cfg.width), kernel, self.cfg.leaky_slope, level)
                )
                c = scaled(c_out, self.cfg.width)
        return nn.Sequential(*layers), c, level

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        S = self.cfg.input_size
        if x.ndim != 4 or x.shape[1:] != (1, S, S):
            raise ValueError(f"expected a (B, 1, {S}, {S}) depth batch, got {tuple(x.shape)}")
        f16 = self.stage16(x)  # (B, c16, S/16, S/16)
        f32 = self.head(self.stage32(f16))  # (B, head, S/32, S/32)
        fine = F.pixel_unshuffle(self.passthrough(f16), 2)  # (B, 4·c_pt, S/32, S/32)
        fused = self.fuse(torch.cat([fine, f32], dim=1))  # (B, head, S/32, S/32)
        return self.out(fused)  # (B, 2 + num_classes, G, G)


def split_output(raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Network output (B, 2 + C, G, G) → offsets (B, G, G, 2) in (0, 1) cell units (u, v),
    via a sigmoid, and class logits (B, G, G, C)."""
    raw = raw.permute(0, 2, 3, 1)  # (B, G, G, 2 + C)
    return torch.sigmoid(raw[..., :NUM_COORDS]), raw[..., NUM_COORDS:]


def conv_layers(model: GraspNet) -> list[nn.Conv2d]:
    """All convolutions, in registration order (= the order ``forward`` runs them)."""
    return [m for m in model.modules() if isinstance(m, nn.Conv2d)]


def count_parameters(model: nn.Module) -> int:
    """Trainable parameters (BatchNorm running statistics are buffers, not counted)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def count_flops(model: GraspNet, input_size: int | None = None) -> int:
    """Multiply-accumulates of all convolutions for one image, from the layer shapes.

    A stride-1 "same" conv at downsampling level ℓ produces (S / 2^ℓ)² outputs, each costing
    k_h·k_w·(C_in / groups)·C_out MACs. BatchNorm, activations, pooling and biases are not
    counted (they are < 1 % of the total).
    """
    S = input_size or model.cfg.input_size
    if S % 32:
        raise ValueError(f"input_size must be a multiple of 32, got {S}")
    total = 0
    for conv in conv_layers(model):
        kh, kw = conv.kernel_size
        side = S >> conv.level
        total += kh * kw * (conv.in_channels // conv.groups) * conv.out_channels * side * side
    return total
