"""Small-vector arithmetic on Python floats gives numpy's bits.

``pipeline.camera.geometry``'s ``cross3``, ``dot3``, ``norm3``, ``rotate_back`` and
``pose_matrix``, and the servo's control law built on them (``pipeline.servo.control``), stand in
for numpy expressions on (3,) arrays. The labels and the closed loop's trials stay the same only
if every float does: each test compares the bits (signed zeros included) with the numpy
expression, or with the law written on numpy arrays, on many random inputs. numpy's dot
products run in the BLAS library it was built with; these tests are what says that its
summation is the one the helpers reproduce on the machine that runs them.

OpenBLAS picks its kernels by CPU, and on some CPUs (AVX-512 ones, for example) its dot product
fuses multiply-adds: one rounding fewer, which no sum of Python floats reproduces. There the
helpers, which are the same on every machine, cannot be numpy's bits. On such a machine
(:func:`_blas_fuses`) the dot products, norms and rotations are checked against the dot
product's error bound instead (both within γ3 Σ|aᵢbᵢ| of the exact sum), ``np.cross`` (no
BLAS) bit for bit as everywhere, and the servo law's comparison with its numpy form is skipped
with the reason.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
from conftest import default_config

from pipeline.camera.geometry import (
    cross3,
    dot3,
    norm3,
    pose_matrix,
    rotate_back,
    rotation_matrices,
)
from pipeline.servo.control import (
    ServoConfig,
    clamp_twist,
    rotation_error,
    servo_velocity,
    warp,
    warp_axis,
    warp_rotation,
)

SERVO = default_config(ServoConfig)


def _bits(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64).view(np.uint64)


def _same(a, b) -> bool:
    """Bit for bit: −0.0 differs from 0.0, NaN equals the same NaN."""
    a, b = _bits(a), _bits(b)
    return a.shape == b.shape and bool(np.all(a == b))


def _vector(rng) -> np.ndarray:
    """A (3,) vector of a random scale with some exact zeros of either sign, or a unit axis."""
    if rng.random() < 0.05:
        v = np.zeros(3)
        v[rng.integers(3)] = rng.choice([-1.0, 1.0])
        return v
    v = rng.normal(size=3) * 10.0 ** rng.uniform(-8, 3)
    draw = rng.random(3)
    v[draw < 0.1] = 0.0
    v[(draw >= 0.1) & (draw < 0.2)] = -0.0
    return v


def _rotation_pose(rng) -> np.ndarray:
    """A (4, 4) pose with a random rotation (some entries exactly ±0) and translation."""
    q = rng.normal(size=4)
    T = pose_matrix(rng.normal(size=3), q / np.linalg.norm(q))
    if rng.random() < 0.2:
        T[:3, :3] = np.round(T[:3, :3])  # axis-aligned: zeros and ±1
        T[:3, :3] *= np.where(rng.random((3, 3)) < 0.5, -1.0, 1.0)  # ±0
    return T


@functools.lru_cache(maxsize=1)
def _blas_fuses() -> bool:
    """Whether numpy's dot of two (3,) arrays on this machine differs from the sum of the
    products in order (``dot3``) on any of 200 random pairs: its BLAS kernel fuses
    multiply-adds."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        a, b = rng.normal(size=3), rng.normal(size=3)
        if float(a @ b) != dot3(a.tolist(), b.tolist()) or float(a @ a) != dot3(
            a.tolist(), a.tolist()
        ):
            return True
    return False


_GAMMA3 = 3 * 2.0**-53 / (1 - 3 * 2.0**-53)  # the error bound of a 3-term dot product


def _same_dot(numpy_value, helper_value, a, b) -> bool:
    """Bit for bit where numpy's BLAS sums in order; where it fuses (:func:`_blas_fuses`), both
    within γ3 Σ|aᵢbᵢ| of the exact dot product of ``a`` and ``b`` (so within twice that of
    each other), elementwise for (3, 3) @ (3,)."""
    if not _blas_fuses():
        return _same(numpy_value, helper_value)
    bound = 2 * _GAMMA3 * (np.abs(np.asarray(a)) @ np.abs(np.asarray(b)))
    diff = np.abs(np.asarray(numpy_value, np.float64) - np.asarray(helper_value, np.float64))
    return bool(np.all(diff <= bound))


def test_cross_dot_norm_and_rotate_back_are_numpys_bits():
    rng = np.random.default_rng(0)
    for _ in range(4000):
        a, b = _vector(rng), _vector(rng)
        la, lb = a.tolist(), b.tolist()
        assert _same(np.cross(a, b), cross3(la, lb)), (a, b)
        assert _same_dot(a @ b, dot3(la, lb), a, b), (a, b)
        assert _same_dot(a.dot(a), dot3(la, la), a, a), a
        n = norm3(la)
        if _blas_fuses():  # sqrt of the dot: within γ3 n of each other, plus each root's rounding
            assert abs(float(np.linalg.norm(a)) - n) <= 2 * _GAMMA3 * n + 2 * math.ulp(n), a
        else:
            assert _same(np.linalg.norm(a), n), a
        T = _rotation_pose(rng)
        Rt = T[:3, :3].T
        assert _same_dot(Rt @ a, rotate_back(T[:3, :3].tolist(), la), Rt, a), (T, a)
        d = a - T[:3, 3]
        assert _same_dot(Rt @ d, rotate_back(T[:3, :3].tolist(), d.tolist()), Rt, d)


def test_all_negative_zero_products_sum_to_positive_zero_as_numpy():
    a, b = [1.0, 2.0, 3.0], [-0.0, -0.0, -0.0]
    assert _same(np.array(a) @ np.array(b), 0.0)
    assert _same(dot3(a, b), 0.0)
    assert _same(rotate_back(np.eye(3).tolist(), b), np.eye(3).T @ np.array(b))


def test_pose_matrix_is_the_rotation_formulas_bits():
    rng = np.random.default_rng(1)
    for i in range(2000):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        position = rng.normal(size=3) * 10.0 ** rng.uniform(-3, 1)
        if i % 3 == 1:
            q, position = q.astype(np.float32), position.astype(np.float32)
        T = np.eye(4)
        T[:3, :3] = rotation_matrices(q)
        T[:3, 3] = position
        assert _same(pose_matrix(position, q), T)
        assert _same(pose_matrix(tuple(position.tolist()), tuple(q.tolist())), T)


# ----------------------------------------------------------------------------- the law on arrays
# The 2.5D visual servoing law as it was written on numpy (3,) arrays before it moved to Python
# floats: the reference the law must match bit for bit.
_N_X, _N_Z = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def _ref_angle(a, b):
    return math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b))


def _ref_axis_angle_to(a, b):
    c = np.cross(a, b)
    s = float(np.linalg.norm(c))
    if s < 1e-12:
        return np.zeros(3)
    return c / s * _ref_angle(a, b)


def _ref_warp_axis(axis, normal):
    a = np.asarray(axis, np.float64)
    n = -np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    rv = _ref_axis_angle_to(n, _N_Z)
    th = float(np.linalg.norm(rv))
    if th > 0:
        k = rv / th
        a = a * math.cos(th) + np.cross(k, a) * math.sin(th) + k * (k @ a) * (1 - math.cos(th))
    a = np.array([a[0], a[1], 0.0])
    return a / np.linalg.norm(a)


def _ref_line_term(axis):
    a = np.array([axis[0], axis[1], 0.0])
    norm = float(np.linalg.norm(a))
    if norm < 1e-9:
        return None
    a /= norm
    if a @ _N_X < 0:
        a = -a
    return _ref_angle(a, _N_X), _ref_axis_angle_to(a, _N_X)


def _ref_signed_term(axis, reference):
    a, r = np.array([axis[0], axis[1], 0.0]), np.array([reference[0], reference[1], 0.0])
    na, nr = float(np.linalg.norm(a)), float(np.linalg.norm(r))
    if na < 1e-9 or nr < 1e-9:
        return None
    a, r = a / na, r / nr
    if a @ r < 0:
        a = -a
    return _ref_angle(a, r), np.array([0.0, 0.0, math.atan2(-a[1], a[0])])


def _ref_rotation_error(normal, long_, short, reference_x=None):
    n_towards = np.asarray(normal, np.float64)
    n = -n_towards / float(np.linalg.norm(n_towards))
    u_theta = _ref_axis_angle_to(n, _N_Z)
    term = _ref_line_term
    if reference_x is not None:
        term = functools.partial(_ref_signed_term, reference=np.asarray(reference_x, np.float64))
    lt, st = term(np.asarray(long_, np.float64)), term(np.asarray(short, np.float64))
    if lt is not None and (st is None or lt[0] < st[0]):
        return u_theta + lt[1], "long"
    if st is not None:
        return u_theta + st[1], "short"
    return u_theta, None


def _ref_servo_velocity(centre, normal, long_, short, off_sign, cfg, dt, reference_x=None):
    lam = cfg.gain / dt if cfg.gain_per_step else cfg.gain
    c = np.asarray(centre, np.float64)
    X, Y, Z = c
    p_e = np.array([X / Z, Y / Z, math.log(Z)])
    p_t = np.array([0.0, off_sign * cfg.cup_offset / cfg.standoff, math.log(cfg.standoff)])
    e_p = p_e - p_t
    u_theta, axis_used = _ref_rotation_error(normal, long_, short, reference_x)
    e = np.concatenate([e_p, u_theta])
    x, y = float(p_e[0]), float(p_e[1])
    rho = c[2] / cfg.standoff
    M = np.zeros((6, 6))
    M[:3, :3] = np.array([[-1.0, 0.0, x], [0.0, -1.0, y], [0.0, 0.0, -1.0]]) / (cfg.standoff * rho)
    M[:3, 3:] = np.array([[x * y, -(1 + x * x), y], [1 + y * y, -x * y, -x], [-y, x, 0.0]])
    M[3:, 3:] = np.eye(3)
    raw = -lam * np.linalg.solve(M, e)
    v, w = float(np.linalg.norm(raw[:3])), float(np.linalg.norm(raw[3:]))
    s_v = min(1.0, cfg.max_linear_speed / v) if v > 0 else 1.0
    s_w = min(1.0, cfg.max_angular_speed / w) if w > 0 else 1.0
    if cfg.uniform_clamp:
        vel, scale = raw * min(s_v, s_w), min(s_v, s_w)
    else:
        vel, scale = np.concatenate([raw[:3] * s_v, raw[3:] * s_w]), min(s_v, s_w)
    rot_deg = math.degrees(float(np.linalg.norm(u_theta)))
    return {
        "velocity": vel,
        "error": e,
        "raw_velocity": raw,
        "scale": scale,
        "feature_error": float(np.linalg.norm(e_p)),
        "rotation_error_deg": rot_deg,
        "linear_speed": float(np.linalg.norm(vel[:3])),
        "angular_speed": float(np.linalg.norm(vel[3:])),
        "axis_used": axis_used,
    }


def _surface(rng):
    """A surface the camera sees: centre in front, normal towards the camera (within ~80° of
    the view line), in-plane axes; camera frame."""
    centre = np.array([rng.normal(0, 0.1), rng.normal(0, 0.1), rng.uniform(0.05, 0.8)])
    normal = -centre / np.linalg.norm(centre) + rng.normal(0, 0.6, 3)
    if rng.random() < 0.1:
        normal = np.array([0.0, 0.0, -1.0])  # fronto-parallel: no warp rotation
    normal /= np.linalg.norm(normal)
    if normal @ centre > 0:
        normal = -normal
    long_ = np.cross(normal, rng.normal(size=3))
    long_ /= np.linalg.norm(long_)
    short = np.cross(normal, long_)
    return centre, normal, long_, short


@pytest.mark.parametrize("gain_per_step,uniform_clamp", [(True, True), (False, False)])
def test_servo_law_is_the_array_laws_bits(gain_per_step, uniform_clamp):
    if _blas_fuses():
        pytest.skip(
            "numpy's BLAS fuses multiply-adds on this CPU: the law on numpy arrays is not the "
            "sum in order that the helpers compute on every machine (module docstring)"
        )
    rng = np.random.default_rng(2)
    cfg = dataclasses.replace(SERVO, gain_per_step=gain_per_step, uniform_clamp=uniform_clamp)
    for i in range(600):
        centre, normal, long_, short = _surface(rng)
        wl, ws = _ref_warp_axis(long_, normal), _ref_warp_axis(short, normal)
        assert _same(warp_axis(long_, normal), wl) and _same(warp_axis(short, normal), ws)
        rotation = warp_rotation(tuple(normal.tolist()))
        assert _same(warp(tuple(long_.tolist()), rotation), wl)
        if i % 4 == 0:  # measured axes (the closed loop's descriptor): float32, not unit
            wl, ws = (np.float32(rng.uniform(0.5, 2.0)) * w.astype(np.float32) for w in (wl, ws))
        reference = rng.normal(size=3) if i % 2 else None
        assert _same(rotation_error(normal, wl, ws), _ref_rotation_error(normal, wl, ws)[0])
        pattern = "LBR"[i % 3]
        ref = _ref_servo_velocity(
            centre, normal, wl, ws, {"L": -1.0, "B": 0.0, "R": 1.0}[pattern], cfg, 1 / 30, reference
        )
        cmd = servo_velocity(centre, normal, wl, ws, pattern, cfg, 1 / 30, reference_x=reference)
        for name, value in ref.items():
            if name == "axis_used":
                assert cmd.axis_used == value
            else:
                assert _same(getattr(cmd, name), value), (i, name)
        assert _same(clamp_twist(ref["raw_velocity"], cfg)[0], ref["velocity"])
