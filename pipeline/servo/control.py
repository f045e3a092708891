"""The 2.5D visual servoing law of the paper (Sec. 5.2, Eqs. 15–27).

Frames and units: everything is in the *current* camera frame, OpenCV axes (x right, y down,
z forward), metres, radians, seconds. The commanded twist ``[V; Ω]`` (6,) is the velocity of the
camera frame's origin (m/s) and its angular velocity (rad/s), both expressed in that camera
frame — what :func:`pipeline.servo.jacobian.camera_jacobian` maps joint velocities to.

Error (Eq. 15) ``e = [p_e − p_e*; uθ]`` (6,):

* ``p_e = [X/Z, Y/Z, log Z]`` (Eq. 16) from the surface centre ``g' = (X, Y, Z)`` in the camera
  frame (:func:`current_features`);
* ``p_e* = [0, off/d*, log d*]`` (Eq. 17), ``off`` = −cup_offset for L, 0 for B, +cup_offset for
  R (Eq. 18; :func:`target_features`). This matches ``pipeline.robot.target_pose``: at the
  target pose the surface centre is seen at camera ``(0, off, d*)``, i.e. under the active cup;
* ``uθ`` (Eqs. 24–27, :func:`rotation_error`) is the rotation of the current camera relative to
  the target camera, so that ``d(uθ)/dt ≈ Ω`` (the ``I3`` block of Eq. 19).

Interaction matrix (Eqs. 19–22, :func:`interaction_matrix`), with ``ρ = Z/d*`` so ``d*ρ = Z``::

    M = [[L_v / (d* ρ), L_w],      L_v = [[-1, 0, x], [0, -1, y], [0, 0, -1]]
         [0,            I3 ]]      L_w = [[xy, -(1+x²), y], [1+y², -xy, -x], [-y, x, 0]]

(derived for a static point: ``Ṗ = −V − Ω × P`` gives ``ẋ``, ``ẏ`` as usual and
``d(log Z)/dt = −V_z/Z − yΩ_x + xΩ_y``, which is the paper's third row).
Its inverse is block upper-triangular: ``M⁻¹ = [[Z L_v⁻¹, −Z L_v⁻¹ L_w], [0, I3]]`` with
``L_v⁻¹ = [[-1, 0, -x], [0, -1, -y], [0, 0, -1]]``.

Control law (Eq. 23): ``[V; Ω] = −λ_eff M⁻¹ e``, i.e. ``Ω = −λ_eff uθ`` and
``V = −λ_eff Z L_v⁻¹ (e_p − L_w uθ)``.

Choices (documented here because the paper leaves them open):

* **Gain per control step** (``ServoConfig.gain_per_step``, true in ``conf/servo/``). Eq. 23 is
  a continuous law and the paper sets λ = 0.4. Read as 0.4 s⁻¹ the error would shrink by e only
  every 2.5 s (a 0.4 m approach would take ~15 s), incompatible with the paper's > 1000 picks
  per hour. We therefore read λ as the discrete gain of one control iteration, as ViSP-style
  loops do (``v = −λ L⁻¹ e`` sent for one period): ``λ_eff = λ / dt``, so one period ``dt``
  removes the fraction λ of the error (to first order). ``gain_per_step=False`` gives the
  literal continuous law ``λ_eff = λ`` (1/s) and ignores ``dt``.
* **Speed limits**: the raw twist is scaled by one common factor
  ``s = min(1, v_max/|V|, ω_max/|Ω|)`` (``ServoConfig.uniform_clamp``, true in ``conf/servo/``).
  Both the linear and the angular part keep their direction *and* their ratio, so the coupling term
  ``−Z L_v⁻¹ L_w uθ`` of V still matches Ω and every error component keeps decaying along the
  same (straight-line) path, only slower. ``uniform_clamp=False`` scales the linear and the
  angular part independently (each keeps its direction, the coupling is lost while clamped).
* **Normal direction**: the project reports surface normals pointing *towards* the camera
  (``normal_cam · center_cam < 0``); the paper's ``n`` of Eq. 24 is the direction the camera Z
  must align with, i.e. pointing *away* from the camera into the surface. We use
  ``n = −normal_cam / |normal_cam|``.
* **Unit rotation axes**: Eq. 24 writes ``(n × n_Z) θ``; ``|n × n_Z| = sin θ``, so taken
  literally the term would be ≈ θ² for small angles. We use the unit axis
  ``(n × n_Z)/|n × n_Z|`` so each term has magnitude θ (the angle-axis ``uθ`` the name and the
  ``I3`` block require). θ is computed as ``atan2(|a × b|, a · b)`` (same as the arccos of
  Eqs. 25–27, accurate near 0).
* **Axes are lines**: a surface axis ``ñ`` and ``−ñ`` are the same line. Each warped axis is
  flipped, if needed, so that its angle to camera X is ≤ 90°; then the one (long or short) with
  the smaller angle is used (Eq. 24: long if ``θ_l < θ_s``, otherwise short).
* **Warped axes live in the image plane**: the descriptor's warped-perspective axes ``ñ_l``,
  ``ñ_s`` are directions in the camera XY plane (the fronto-parallel view of the surface). Any z
  component is dropped before the second term is computed, so that term is a pure rotation
  about camera Z and does not count the tilt again (the first term handles the tilt). For 3D
  in-surface axes that are not warped yet, :func:`warp_axis` does the warp (rotates them with
  the minimal rotation taking ``n`` onto ``n_Z``).
* **Convergence**: ``|x − x*| < tolerance_xy``, ``|y − y*| < tolerance_xy`` (normalised image
  coordinates), ``|log Z − log d*| < tolerance_log_z`` and ``|uθ| < tolerance_rot_deg``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from pipeline.camera.geometry import cross3, dot3, norm3
from pipeline.config.build import from_section

_N_X = (1.0, 0.0, 0.0)
_N_Z = (0.0, 0.0, 1.0)
_OFF_SIGN = {"L": -1.0, "B": 0.0, "R": 1.0}  # Eq. 18, in units of cup_offset


@dataclass
class ServoConfig:
    """Parameters of the 2.5D visual servoing law (paper Sec. 5.2). Metres, radians, seconds.

    The ``servo`` section with d* and the cup offset from ``hand`` and ``target_point`` given
    by the caller (None: Eqs. 17–18's goal), built by :func:`servo_config`."""

    gain: float  # λ of Eq. 23 (per control step when gain_per_step, else 1/s)
    standoff: float  # d* (m), Eqs. 17, 22, 23
    cup_offset: float  # |off| of Eq. 18 (m)
    tolerance_xy: float  # converged when |x − x*|, |y − y*| (normalised coords) below ...
    tolerance_log_z: float  # ... |log Z − log d*| below this ...
    tolerance_rot_deg: float  # ... and |uθ| below this (degrees)
    max_linear_speed: float  # m/s, camera (clamp keeping the direction)
    max_angular_speed: float  # rad/s
    gain_per_step: bool  # λ is the discrete gain of one period dt: λ_eff = λ/dt
    uniform_clamp: bool  # one scale factor for V and Ω (keeps their ratio)
    # (3,) desired position of the surface centre in the camera frame at the goal (m), or None:
    # a goal other than Eqs. 17–18's (the closed loop's pre-grasp above the grasp pose)
    target_point: tuple | None


def servo_config(cfg) -> ServoConfig:
    """The ``ServoConfig`` of a composed config: ``cfg.servo`` (gain, tolerances, speed
    limits), d* and the cup offset from ``cfg.hand``, the goal of Eqs. 17–18."""
    return from_section(
        ServoConfig,
        cfg.servo,
        standoff=float(cfg.hand.standoff),
        cup_offset=float(cfg.hand.cup_offset),
        target_point=None,
    )


@dataclass
class ServoCommand:
    """One output of :func:`servo_velocity`.

    Attributes:
        velocity: (6,) camera-frame twist ``[V (m/s), Ω (rad/s)]`` after the speed clamp.
        error: (6,) ``e = [p_e − p_e*; uθ]`` of Eq. 15 (normalised coords, log-metres, rad).
        converged: every tolerance of :class:`ServoConfig` met.
        raw_velocity: (6,) the twist of Eq. 23 before the clamp.
        scale: the clamp factor(s) applied, ≤ 1 (the smaller one when clamped separately).
        feature_error: ``|p_e − p_e*|``.
        rotation_error_deg: ``|uθ|`` in degrees.
        linear_speed: ``|V|`` after the clamp, m/s.
        angular_speed: ``|Ω|`` after the clamp, rad/s.
        axis_used: "long" or "short": which warped axis camera X is aligned with (None when
            neither has an image-plane direction).
    """

    velocity: np.ndarray
    error: np.ndarray
    converged: bool
    raw_velocity: np.ndarray
    scale: float
    feature_error: float
    rotation_error_deg: float
    linear_speed: float
    angular_speed: float
    axis_used: str | None


def _pattern_name(pattern) -> str:
    name = getattr(pattern, "name", pattern)  # accepts "L" or GraspClass.L
    if name not in _OFF_SIGN:
        raise ValueError(f"grasp pattern must be one of L, R, B (got {pattern!r})")
    return name


# The law runs on Python floats: a few dozen operations on 3-vectors per control period, where
# numpy's per-call overhead would cost more than the arithmetic. The helpers of
# pipeline.camera.geometry (cross3, dot3, norm3) give numpy's bits, so every float here is the
# one the same formulas give on (3,) arrays.
Vec3 = tuple[float, float, float]


def _vec3(v, what: str) -> Vec3:
    """``v`` as three finite float64 values (a tuple), else ValueError."""
    if type(v) is tuple and len(v) == 3 and all(type(c) is float for c in v):
        a = v
    else:
        arr = np.asarray(v, dtype=np.float64).reshape(-1)
        if arr.shape != (3,):
            raise ValueError(f"{what} must be a finite (3,) vector, got {v!r}")
        a = tuple(arr.tolist())
    if not (math.isfinite(a[0]) and math.isfinite(a[1]) and math.isfinite(a[2])):
        raise ValueError(f"{what} must be a finite (3,) vector, got {v!r}")
    return a


def _angle(a: Vec3, b: Vec3) -> float:
    """Angle between two vectors (rad), atan2 form of the arccos of Eqs. 25–27."""
    return math.atan2(norm3(cross3(a, b)), dot3(a, b))


def _axis_angle_to(a: Vec3, b: Vec3) -> Vec3:
    """``(a × b)/|a × b| · θ(a, b)``: the rotation taking direction ``a`` onto ``b`` (3,)."""
    c = cross3(a, b)
    s = norm3(c)
    if s < 1e-12:
        return (0.0, 0.0, 0.0)  # parallel (θ = 0); antiparallel cannot happen for visible surfaces
    theta = math.atan2(s, dot3(a, b))  # _angle(a, b)
    return (c[0] / s * theta, c[1] / s * theta, c[2] / s * theta)


def target_features(pattern, cfg: ServoConfig) -> np.ndarray:
    """``p_e*`` (3,) of Eqs. 17–18: ``[0, off/d*, log d*]``, off = −/0/+ cup_offset for L/B/R;
    or, with ``cfg.target_point``, that point's features (Eq. 16)."""
    return np.array(_target_features(pattern, cfg))


def _target_features(pattern, cfg: ServoConfig) -> Vec3:
    if cfg.target_point is not None:
        return _features(_vec3(cfg.target_point, "center_cam"))
    off = _OFF_SIGN[_pattern_name(pattern)] * cfg.cup_offset
    return (0.0, off / cfg.standoff, math.log(cfg.standoff))


def current_features(center_cam) -> np.ndarray:
    """``p_e`` (3,) of Eq. 16: ``[X/Z, Y/Z, log Z]`` of the surface centre (camera frame, m)."""
    return np.array(_features(_vec3(center_cam, "center_cam")))


def _features(center: Vec3) -> Vec3:
    X, Y, Z = center
    if Z <= 0:
        raise ValueError(f"the surface centre must be in front of the camera (Z > 0), got Z={Z}")
    return (X / Z, Y / Z, math.log(Z))


def warp_axis(axis_cam, normal_cam) -> np.ndarray:
    """A 3D in-surface axis seen in the fronto-parallel (warped) view, camera frame (3,).

    Rotates ``axis_cam`` by the minimal rotation that takes the away-from-camera normal
    ``n = −normal_cam`` onto camera Z (what the warped-perspective transformation of Sec. 5.1
    does to the surface), so the result lies in the camera XY plane. ``normal_cam`` points
    towards the camera (project convention). Returns a unit vector with z = 0.
    """
    return np.array(_warp(_vec3(axis_cam, "axis_cam"), warp_rotation(normal_cam)))


def warp_rotation(normal_cam) -> tuple[Vec3, float, float, float] | None:
    """The rotation of :func:`warp_axis` for one normal (3,), towards the camera: its unit axis,
    cos θ, sin θ and 1 − cos θ; None when the normal is along camera Z already. For warping
    several axes of one surface (:func:`warp`)."""
    n0, n1, n2 = _vec3(normal_cam, "normal_cam")
    n = (-n0, -n1, -n2)
    length = norm3(n)
    if length == 0.0:
        raise ValueError("normal_cam has zero length")
    n = (n[0] / length, n[1] / length, n[2] / length)
    rv = _axis_angle_to(n, _N_Z)
    th = norm3(rv)
    if not th > 0:
        return None
    k = (rv[0] / th, rv[1] / th, rv[2] / th)  # Rodrigues
    c = math.cos(th)
    return k, c, math.sin(th), 1 - c


def warp(axis_cam, rotation: tuple[Vec3, float, float, float] | None) -> Vec3:
    """:func:`warp_axis` of ``axis_cam`` (3,) with the normal's :func:`warp_rotation`, as a
    tuple of floats."""
    return _warp(_vec3(axis_cam, "axis_cam"), rotation)


def _warp(a: Vec3, rotation) -> Vec3:
    if rotation is not None:
        k, c, s, c1 = rotation
        ka = dot3(k, a)
        x = cross3(k, a)
        # a cos θ + (k × a) sin θ + k (k · a)(1 − cos θ), summed as numpy sums the arrays
        a = (
            a[0] * c + x[0] * s + k[0] * ka * c1,
            a[1] * c + x[1] * s + k[1] * ka * c1,
            a[2] * c + x[2] * s + k[2] * ka * c1,
        )
    a = (a[0], a[1], 0.0)
    norm = norm3(a)
    if norm < 1e-9:
        raise ValueError("axis_cam is parallel to the normal")
    return (a[0] / norm, a[1] / norm, a[2] / norm)


def _line_term(axis: Vec3) -> tuple[float, Vec3] | None:
    """(angle to X, rotation term) of one warped axis taken as a line in the image plane."""
    a = (axis[0], axis[1], 0.0)  # image-plane direction (see module docstring)
    norm = norm3(a)
    if norm < 1e-9:
        return None
    a = (a[0] / norm, a[1] / norm, a[2] / norm)
    if dot3(a, _N_X) < 0:  # an axis is a line: take the direction within 90° of X
        a = (-a[0], -a[1], -a[2])
    return _angle(a, _N_X), _axis_angle_to(a, _N_X)


def _signed_term(axis: Vec3, reference: Vec3) -> tuple[float, Vec3] | None:
    """(angle to the reference, rotation term) of a warped axis signed to within 90° of the
    image-plane ``reference``: the term turns the camera about Z until that signed axis is its
    X, by the signed in-plane angle atan2((a × X)_z, a · X), which stays defined at 180°."""
    a = (axis[0], axis[1], 0.0)
    r = (reference[0], reference[1], 0.0)
    na, nr = norm3(a), norm3(r)
    if na < 1e-9 or nr < 1e-9:
        return None
    a = (a[0] / na, a[1] / na, a[2] / na)
    r = (r[0] / nr, r[1] / nr, r[2] / nr)
    if dot3(a, r) < 0:
        a = (-a[0], -a[1], -a[2])
    return _angle(a, r), (0.0, 0.0, math.atan2(-a[1], a[0]))


def _rotation_error(
    normal_cam, warped_long, warped_short, reference_x=None
) -> tuple[Vec3, str | None]:
    n_towards = _vec3(normal_cam, "normal_cam")
    norm = norm3(n_towards)
    if norm < 1e-12:
        raise ValueError("normal_cam has zero length")
    # paper's n: the direction camera Z must align with (away from camera)
    n = (-n_towards[0] / norm, -n_towards[1] / norm, -n_towards[2] / norm)
    u_theta = _axis_angle_to(n, _N_Z)  # first term of Eq. 24 (unit axis × θ_{n,n_Z})
    if reference_x is None:  # the paper: the axis line nearest camera X
        term = _line_term
    else:  # the hand's X is given (a turned hand): the axis nearest it, signed towards it
        ref = _vec3(reference_x, "reference_x")
        term = functools.partial(_signed_term, reference=ref)
    long_ = term(_vec3(warped_long, "warped_long"))
    short = term(_vec3(warped_short, "warped_short"))
    if long_ is not None and (short is None or long_[0] < short[0]):
        t = long_[1]
        return (u_theta[0] + t[0], u_theta[1] + t[1], u_theta[2] + t[2]), "long"
    if short is not None:
        t = short[1]
        return (u_theta[0] + t[0], u_theta[1] + t[1], u_theta[2] + t[2]), "short"
    return u_theta, None


def rotation_error(normal_cam, warped_long, warped_short) -> np.ndarray:
    """``uθ`` (3,) of Eqs. 24–27, radians, current camera frame.

    ``uθ = u(n, n_Z) θ(n, n_Z) + u(ñ, n_X) θ(ñ, n_X)`` with ``u(a, b) = (a × b)/|a × b|``:
    the first term takes the away-from-camera normal ``n = −normal_cam`` onto camera Z, the
    second the warped axis ``ñ`` (long or short, whichever line is nearer to camera X, each
    signed to within 90° of X, z dropped) onto camera X. ``Ω = −λ uθ`` turns the camera's Z
    towards ``n`` and its X towards ``ñ``.

    Args:
        normal_cam: (3,) surface normal pointing towards the camera (project convention).
        warped_long, warped_short: (3,) warped-perspective long and short axes (image-plane
            directions; sign and length do not matter).
    """
    return np.array(_rotation_error(normal_cam, warped_long, warped_short)[0])


def interaction_matrix(p_e, Z: float, cfg: ServoConfig) -> np.ndarray:
    """``M`` (6, 6) of Eqs. 19–22: ``[[L_v/(d* ρ), L_w], [0, I3]]``, ρ = Z/d*.

    ``p_e`` (3,) current features (only x, y are used), ``Z`` the centre's depth (m).
    """
    x, y = float(p_e[0]), float(p_e[1])
    rho = Z / cfg.standoff
    d = cfg.standoff * rho
    # L_v = [[-1, 0, x], [0, -1, y], [0, 0, -1]] divided by d* ρ, entry by entry
    return np.array(
        [
            [-1.0 / d, 0.0 / d, x / d, x * y, -(1 + x * x), y],
            [0.0 / d, -1.0 / d, y / d, 1 + y * y, -x * y, -x],
            [0.0 / d, 0.0 / d, -1.0 / d, -y, x, 0.0],
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    )


def clamp_twist(twist, cfg: ServoConfig) -> tuple[np.ndarray, float]:
    """The twist (6,) limited to ``max_linear_speed`` / ``max_angular_speed``, and the scale.

    Uniform (``uniform_clamp``): one factor for all six components. Otherwise the linear and angular
    parts are scaled separately (the returned scale is the smaller factor). Directions are kept.
    """
    t = np.asarray(twist, dtype=np.float64).reshape(6)
    values = t.tolist()
    v, w = norm3(values[:3]), norm3(values[3:])
    s_v = min(1.0, cfg.max_linear_speed / v) if v > 0 else 1.0
    s_w = min(1.0, cfg.max_angular_speed / w) if w > 0 else 1.0
    if cfg.uniform_clamp:
        s = min(s_v, s_w)
        return t * s, s
    return np.concatenate([t[:3] * s_v, t[3:] * s_w]), min(s_v, s_w)


def servo_velocity(
    center_cam,
    normal_cam,
    warped_long,
    warped_short,
    pattern,
    cfg: ServoConfig,
    dt: float | None = None,
    reference_x=None,
) -> ServoCommand:
    """Eq. 23: the camera twist that drives ``e`` to zero, clamped to the speed limits.

    Args:
        center_cam: (3,) surface centre g' in the current camera frame, metres (Z > 0).
        normal_cam: (3,) surface normal towards the camera.
        warped_long, warped_short: (3,) warped-perspective surface axes (image-plane directions).
        pattern: "L", "B" or "R" (or an enum member with that name).
        cfg: the servo parameters.
        dt: the control period (s); required when ``cfg.gain_per_step`` (λ_eff = λ/dt).
        reference_x: (3,) optional, current camera frame: where the hand's X should point (a
            hand turned about the normal, ``hand.rotations_deg``). The warped axis nearest it,
            signed towards it, is aligned with camera X. None: the paper's rule (the axis line
            nearest camera X).

    Returns:
        :class:`ServoCommand` with the camera-frame twist ``[V; Ω]`` (6,).
    """
    if cfg.gain_per_step:
        if dt is None or dt <= 0:
            raise ValueError("servo_velocity needs the control period dt > 0 when gain_per_step")
        lam = cfg.gain / dt
    else:
        lam = cfg.gain
    center = _vec3(center_cam, "center_cam")
    p_e = _features(center)
    p_t = _target_features(pattern, cfg)
    e_p = (p_e[0] - p_t[0], p_e[1] - p_t[1], p_e[2] - p_t[2])
    u_theta, axis_used = _rotation_error(normal_cam, warped_long, warped_short, reference_x)
    e = np.array(e_p + u_theta)
    M = interaction_matrix(p_e, center[2], cfg)
    raw = -lam * np.linalg.solve(M, e)
    vel, scale = clamp_twist(raw, cfg)
    rot_deg = math.degrees(norm3(u_theta))
    converged = bool(
        abs(e_p[0]) < cfg.tolerance_xy
        and abs(e_p[1]) < cfg.tolerance_xy
        and abs(e_p[2]) < cfg.tolerance_log_z
        and rot_deg < cfg.tolerance_rot_deg
    )
    speeds = vel.tolist()
    return ServoCommand(
        velocity=vel,
        error=e,
        converged=converged,
        raw_velocity=raw,
        scale=scale,
        feature_error=norm3(e_p),
        rotation_error_deg=rot_deg,
        linear_speed=norm3(speeds[:3]),
        angular_speed=norm3(speeds[3:]),
        axis_used=axis_used,
    )
