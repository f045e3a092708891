"""Depth preprocessing before planning (``conf/depth_filter/*.yaml``): hole filling, median.

A structured-light camera leaves holes (no data, 0) in the projector's shadow beside box edges
and on steep faces, and adds noise that grows with depth (``pipeline.camera.sensor``). Two
filters, in this order, both off by default (``depth_filter=none``):

* **Hole filling** (``fill_holes_px`` = n passes), "farthest from around" like librealsense's
  ``hole_filling_filter`` mode 1, kept to a hole's far side: pass by pass, a pixel without
  data takes the largest depth among its 3 × 3 neighbours with data, but only when that depth
  is within ``edge_jump`` (1 cm) of the farthest depth with data within 2n + 1 pixels of it
  (single-pixel spikes, removed by a 3 × 3 opening, do not count).
  A projector shadow lies on the far surface beside a depth step, so it closes from the
  floor's side only (filling it from the near side would grow the box into the gap); a hole
  inside one face (depths within 1 cm) closes from all sides, n pixels from each. A shadow
  band closes when it is at most n pixels wide (the SR300's is about 3 px beside a 10 cm
  step). Holes on steep faces, whose depth changes by more than 1 cm within 2n + 1 pixels,
  mostly stay; pixels still without data keep 0.
* **Median** (``median_px``, 3 or 5): the median of the pixels *with data* in a
  ``median_px`` × ``median_px`` window, which removes per-pixel noise and keeps steps; pixels
  without data stay 0 and do not pull their neighbours towards 0.

Images are (H, W) float32 metres, 0 = no data, in and out.
"""

from __future__ import annotations

import cv2
import numpy as np

_KERNEL = np.ones((3, 3), np.uint8)
EDGE_JUMP_M = 0.01  # a fill within this of the farthest depth nearby comes from the far side


def fill_holes(depth_m: np.ndarray, iterations: int, edge_jump: float = EDGE_JUMP_M) -> np.ndarray:
    """Fill pixels without data (0) from their far side, ``iterations`` passes
    (module docstring). Returns a new float32 array; pixels with data are unchanged."""
    out = np.asarray(depth_m, np.float32).copy()
    holes = out <= 0
    if not holes.any() or not (~holes).any() or int(iterations) <= 0:
        return out
    # the farthest depth with data near each pixel: a hole's far side within reach of the fill
    reach = 4 * int(iterations) + 3  # 2n + 1 pixels either way: holes up to 2n + 1 px wide
    # (after a 3 × 3 opening: a single far pixel, a noise spike, does not count as a far side)
    opened = cv2.morphologyEx(out, cv2.MORPH_OPEN, _KERNEL)
    local_far = cv2.dilate(opened, np.ones((reach, reach), np.uint8))
    floor = local_far - np.float32(edge_jump)  # accept fills from the far side only
    for _ in range(int(iterations)):
        grown = cv2.dilate(out, _KERNEL)
        take = (out <= 0) & (grown > 0) & (grown >= floor)
        if not take.any():
            break
        out[take] = grown[take]
    return out


def median_filter(depth_m: np.ndarray, ksize: int) -> np.ndarray:
    """``ksize`` × ``ksize`` median (3 or 5) over the pixels with data; pixels without data
    stay 0. (``cv2.medianBlur`` where the window is all data; an exact sort of the window's
    pixels with data where it is not, about a fifth of the pixels on SR300 depth.)"""
    if ksize not in (3, 5):
        raise ValueError(f"depth_filter.median_px={ksize}: use 0 (off), 3 or 5")
    depth = np.ascontiguousarray(depth_m, np.float32)
    valid = depth > 0
    out = cv2.medianBlur(depth, ksize)
    near_hole = valid & (
        cv2.dilate((~valid).astype(np.uint8), np.ones((ksize, ksize), np.uint8)) > 0
    )
    if near_hole.any():
        r = ksize // 2
        padded = np.pad(np.where(valid, depth, np.inf), r, constant_values=np.inf)
        windows = np.lib.stride_tricks.sliding_window_view(padded, (ksize, ksize))
        vs, us = np.nonzero(near_hole)
        w = np.sort(windows[vs, us].reshape(len(vs), ksize * ksize), axis=1)
        n = np.isfinite(w).sum(axis=1)  # >= 1: the pixel itself has data
        rows = np.arange(len(vs))
        out[vs, us] = 0.5 * (w[rows, (n - 1) // 2] + w[rows, n // 2])
    return np.where(valid, out, np.float32(0.0)).astype(np.float32)


def preprocess_depth(depth_m: np.ndarray, cfg) -> np.ndarray:
    """Apply the filters ``cfg`` (a ``DepthFilterConfig``) switches on; the input itself when
    none is on."""
    if cfg is None or (int(cfg.fill_holes_px) <= 0 and int(cfg.median_px) <= 0):
        return depth_m
    out = np.asarray(depth_m, np.float32)
    if int(cfg.fill_holes_px) > 0:
        out = fill_holes(out, int(cfg.fill_holes_px))
    if int(cfg.median_px) > 0:
        out = median_filter(out, int(cfg.median_px))
    return out
