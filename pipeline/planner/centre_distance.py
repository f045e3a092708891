"""Table 2 of the paper (Sec. 8.1.1): how close each planner's optimal grasp point lies to the
centre of a real surface.

Definition (the paper's, made exact here and printed in the report):

* **Truth.** The centres of the *true* visible box faces of the image, from the simulator's box
  poses and instance mask (``pipeline.grasping.surfaces.true_visible_faces``, faces with at
  least ``surfaces.truth_min_visible_px`` visible pixels): the centre of each face's visible
  region, projected to pixels. Not the labelling stage's detected surfaces.
* **Distance.** For each test image, the pixel distance from the planner's optimal grasp point
  (G_opt: the first ranked candidate) to the nearest true centre.
* **Within r px.** The share of images whose distance is less than r (the paper: "less than 30
  pixels"). Images with no visible face are skipped; an image where a planner returns no grasp
  counts as a miss for that planner (distance = inf), so every planner is scored over the same
  images. The earlier definition, "at most r", is kept as a labelled column of the report
  (``inclusive=True``).
"""

from __future__ import annotations

import numpy as np

PAPER_TABLE2 = {"dexnet4": 0.5888, "ours": 0.7916}  # within 30 px, paper Table 2
PAPER_RADIUS_PX = 30.0


def nearest_centre_distance(point_uv: np.ndarray | None, centres_uv: np.ndarray) -> float:
    """Pixel distance from ``point_uv`` (2,) to the nearest of ``centres_uv`` (M, 2).

    ``inf`` when there is no point (the planner found no grasp); ``nan`` when there are no
    centres (the image is not scored).
    """
    centres = np.asarray(centres_uv, np.float64).reshape(-1, 2)
    if len(centres) == 0:
        return float("nan")
    if point_uv is None or not np.all(np.isfinite(point_uv)):
        return float("inf")
    return float(np.min(np.linalg.norm(centres - np.asarray(point_uv, np.float64), axis=1)))


def within_rate(distances: np.ndarray, radius_px: float, inclusive: bool = False) -> float:
    """Share of scored images (finite or inf distance; nan skipped) closer than ``radius_px``
    (``inclusive``: at most ``radius_px``, the earlier definition)."""
    d = np.asarray(distances, np.float64)
    d = d[~np.isnan(d)]
    if not len(d):
        return float("nan")
    return float(np.mean(d <= radius_px if inclusive else d < radius_px))


def within_curve(distances: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """``within_rate`` at each radius: (R,)."""
    return np.array([within_rate(distances, float(r)) for r in radii])
