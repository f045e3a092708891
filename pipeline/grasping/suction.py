"""The suction cup's physical model, shared by labelling, the Dex-Net-style planner's labels and
the simulated world: the cup's settings and the hold test of k = 1 or 2 sealed cups.

Users: ``pipeline.labelling.scene`` (the hold check of the labels), ``pipeline.dexnet.contact``
(the single-cup rules of the Dex-Net-style labels) and ``pipeline.world.suction`` (the
simulated gripper, which runs the hold test on the box it has sealed on). The model is pure
arithmetic: no simulator, no image.

Hold test (:func:`hold_test`), the static weight of the box only (contact.py rule 4), extended
to k = 1 or 2 cups with contact points x_i (the centre rays' hits), approach axis a, weight
F = m g (``gravity_world`` is the gravity acceleration vector, m/s², e.g. (0, 0, −9.81); the
gripper reads it from the engine), centre of mass c. The cups act as one contact at the
centroid x̄ of the x_i:

- ``pull``: f_pull = F . a, normal force f_N = k V − f_pull; fails when f_N < 0.
- ``shear``: |F − (F . a) a| ≤ mu f_N (one friction cone for the total normal force).
- ``torsion``: tau = (c − x̄) × F; |tau . a| ≤ mu f_N l_t with l_t = r for one cup and
  l_t = max(r, cup_offset) for two: the friction couple of the two cups, mu f_N / 2 at
  ±cup_offset from x̄; each cup's own ring torsion is not added. This is conservative: the
  exact limit is mu f_N times the mean distance of the rims' points from x̄, which lies between
  cup_offset and cup_offset + r (0.0356 m vs 0.035 m for the paper's hand), while the simple sum
  r + cup_offset (0.044 m) would overestimate it.
- ``bending``: the in-plane part of tau is split into tau_u about the cup line u (x_2 − x_1
  projected off a) and tau_w about w = a × u. About u the box pivots on the cups' rims: lever
  r. About w it peels one cup off while pivoting on the outer rim of the other, and the vacuum
  acts at x̄: lever l_w = r + cup_offset (r for one cup). Holds when
  (tau_u / (f_N r))² + (tau_w / (f_N l_w))² ≤ 1, evaluated as
  sqrt((tau_u / r)² + (tau_w / l_w)²) ≤ f_N (no division by f_N). With one cup both levers
  are r and it is contact.py's |tau_perp| ≤ r f_N.

``HoldResult.margin`` is min over the rules of limit / demand − 1 (inf for a rule with no
demand), for logging; it is negative when a rule fails. With f_N < 0 it is the pull margin
k V / f_pull − 1 alone (every other limit is then negative, and contact.py's inequalities
call those rules failed too, but "pull" comes first).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.config.build import from_section


@dataclass
class SuctionModelConfig:
    """Settings of the suction contact model (SI units: metres, newtons, kilograms, seconds):
    ``conf/suction/`` with the cup radius, g and the box density given by the caller, built by
    :func:`suction_model_config`.

    Attributes:
        cup_radius: radius of the cup's rim, m (the paper's cup: 18 mm diameter).
        vacuum_force: force with which the vacuum pulls the object onto one cup, N
            (50 kPa x cup area).
        friction: friction coefficient mu between cup and box.
        compliance: largest spread of the rim's contact heights along the approach axis that
            still seals, m.
        ring_points: K, points on the cup's rim.
        visibility_tolerance: a rim point counts as free when the depth image at its pixel is
            within this of its z, m.
        gravity: g, m/s^2.
        density: box density, kg/m^3; mass = density x volume, centre of mass = box centre.
        perturbations: perturbed grasps per candidate in ``robust_quality``.
        sigma_position: standard deviation of each in-plane component of the contact point's
            shift, m.
        sigma_axis_deg: standard deviation of the approach axis tilt, degrees.
        quality_threshold: a robust quality at or above this is a positive label (Dex-Net 4.0).
    """

    cup_radius: float
    vacuum_force: float
    friction: float
    compliance: float
    ring_points: int
    visibility_tolerance: float
    gravity: float
    density: float
    perturbations: int
    sigma_position: float
    sigma_axis_deg: float
    quality_threshold: float


def box_mass(box, density: float) -> float:
    """A box's mass, kg: its own ``mass`` where it has one (cartons drawn per box), else
    ``density`` (kg/m³) × the volume of its ``size`` (3,) m."""
    mass = getattr(box, "mass", None)
    return float(mass) if mass is not None else float(density) * float(np.prod(box.size))


def suction_model_config(cfg, density: float) -> SuctionModelConfig:
    """The suction contact model of a composed config: ``conf/suction/`` with the cup radius
    (``hand.cup_diameter`` / 2), g (``|physics.gravity|``) and the boxes' ``density`` (kg/m³:
    ``boxes.density`` for generated heaps, ``eval_boxes.density`` for the closed loop's boxes)."""
    return from_section(
        SuctionModelConfig,
        cfg.suction,
        cup_radius=float(cfg.hand.cup_diameter) / 2.0,
        gravity=abs(float(cfg.physics.gravity)),
        density=float(density),
    )


@dataclass
class HoldResult:
    """Outcome of :func:`hold_test`.

    Attributes:
        ok: the seal holds the box's weight.
        reason: "ok" or the first failing rule: "pull", "shear", "torsion", "bending".
        margin: min over the rules of limit / demand − 1 (for logging; < 0 when a rule fails,
            inf when nothing loads the contact).
    """

    ok: bool
    reason: str
    margin: float


def _ratio_margin(limit: float, demand: float) -> float:
    """limit / demand − 1; a rule with no demand (<= 0) has an infinite margin."""
    if demand <= 1e-15:
        return math.inf
    return limit / demand - 1.0


def hold_test(
    mass: float,
    com_world,
    contact_points,
    axis,
    gravity_world,
    model_cfg: SuctionModelConfig,
    cup_offset: float,
) -> HoldResult:
    """Whether k (1 or 2) sealed cups hold a box's static weight (module docstring rules).

    Args:
        mass: the box's mass, kg.
        com_world: (3,) its centre of mass, m.
        contact_points: (k, 3) the cups' contact points (under each cup's centre), m.
        axis: (3,) approach axis, pointing from the cups into the box; normalised here.
        gravity_world: (3,) gravity acceleration vector, m/s² (the weight is mass × this).
        model_cfg: vacuum force V per cup, friction mu, cup radius r.
        cup_offset: distance of each cup from the cups' midpoint, m (0.035 for the paper's
            hand); only used with two cups.

    Returns:
        A :class:`HoldResult`.
    """
    x = np.atleast_2d(np.asarray(contact_points, dtype=np.float64))
    k = len(x)
    if k not in (1, 2) or x.shape[1] != 3:
        raise ValueError(f"contact_points must be (1, 3) or (2, 3), not {x.shape}")
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    F = float(mass) * np.asarray(gravity_world, dtype=np.float64)
    r, mu = model_cfg.cup_radius, model_cfg.friction
    vacuum = k * model_cfg.vacuum_force

    f_pull = float(F @ a)
    f_n = vacuum - f_pull
    shear = float(np.linalg.norm(F - f_pull * a))
    tau = np.cross(np.asarray(com_world, dtype=np.float64) - x.mean(axis=0), F)
    tau_axial = float(tau @ a)
    tau_perp = tau - tau_axial * a
    if k == 1:
        lever_t, lever_w = r, r
        bend = float(np.linalg.norm(tau_perp)) / r
    else:
        u = x[1] - x[0]
        u = u - (u @ a) * a
        norm_u = np.linalg.norm(u)
        if norm_u < 1e-9:
            raise ValueError("the two contact points coincide across the axis")
        u /= norm_u
        w = np.cross(a, u)
        lever_t, lever_w = max(r, cup_offset), r + cup_offset
        bend = math.hypot(float(tau_perp @ u) / r, float(tau_perp @ w) / lever_w)

    fails = {
        "pull": f_n < 0.0,
        "shear": shear > mu * f_n,
        "torsion": abs(tau_axial) > lever_t * mu * f_n,
        "bending": bend > f_n,
    }
    margin = _ratio_margin(vacuum, f_pull)
    if f_n >= 0.0:  # with f_N < 0 the other limits are negative: only the pull margin means much
        margin = min(
            margin,
            _ratio_margin(mu * f_n, shear),
            _ratio_margin(lever_t * mu * f_n, abs(tau_axial)),
            _ratio_margin(f_n, bend),
        )
    reason = next((name for name, failed in fails.items() if failed), "ok")
    return HoldResult(reason == "ok", reason, float(margin))
