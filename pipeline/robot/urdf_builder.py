"""Writes ``urdf/binpick_robot.urdf``: an xArm6 arm, a 1-DoF hand tilt, a camera and two cups.

The URDF file is committed; this module is how it was made, so its geometry can be read and
changed in one place. Regenerate after an edit with::

    .venv/bin/python -c "from pipeline.robot.urdf_builder import write_urdf; write_urdf()"

(``tests/test_robot.py`` checks that the committed file matches this module's output.)

Arm: joint origins, axes and limits copied from pybullet_data's ``xarm/xarm6_robot.urdf``
(UFactory xArm6, 0.7 m reach); the meshes are replaced by cylinders of about the real links'
girth, so the file needs no external mesh.

Hand (paper Fig. 1b, c), all lengths in metres:

* ``joint7`` ("hand tilt"): revolute, parent ``link6`` (the flange; its z axis points out of the
  flange face), child ``hand``. Its axis is the flange's y axis, which is parallel to the camera's
  Y axis and so to the line through the two cups: the hand nods the camera's optical axis within
  the camera's X–Z plane. Pivot ``HAND_PIVOT_FROM_FLANGE`` along the flange z; limits ±90°.
* ``camera`` (fixed to ``hand``): ``CAMERA_FROM_PIVOT`` further along the hand's z. Its frame is
  the OpenCV optical frame: x right, y down in the image, z = viewing direction. At tilt 0 it is
  the flange frame translated along z (same axes).
* ``cup_left`` / ``cup_right`` (fixed to ``camera``): frame origin at the centre of the cup's
  tip disc (the sealing lip), axes parallel to the camera's. Left is camera y = −0.035, right
  is camera y = +0.035 (paper Eq. 18: off = −0.035 m for L, +0.035 m for R along camera Y;
  camera Y points down in the image, so the LEFT cup is the one on the image's TOP side).
  Tips at camera z = ``CUP_TIP_Z`` = 0.14: at the paper's target pose (optical centre
  d* = 0.15 m from the surface along its normal) the lips hover 10 mm above the surface, and
  a final 10 mm move along camera z makes contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

URDF_PATH = Path(__file__).parent / "urdf" / "binpick_robot.urdf"

HAND_PIVOT_FROM_FLANGE = 0.04  # flange face → hand tilt axis, along the flange z
CAMERA_FROM_PIVOT = 0.08  # tilt axis → optical centre, along the hand z
CUP_OFFSET = 0.035  # cup centre ↔ optical centre, along camera y (paper Fig. 1b)
CUP_DIAMETER = 0.018  # paper Sec. 2
CUP_TIP_Z = 0.14  # cup lip ahead of the optical centre, along camera z
CUP_PAD_LENGTH = 0.025  # the 18 mm bellows/pad at the cup's end
CUP_ROD_RADIUS = 0.005  # the vacuum rod behind the pad
HAND_TILT_LIMIT = math.pi / 2

# xArm6 (pybullet_data/xarm/xarm6_robot.urdf): (name, parent, child, xyz, rpy, lower, upper,
# effort). Every axis is the child frame's z. Joints 1, 4 and 6 turn +-_TURN: 2 pi (rad) as that
# file writes it.
_TURN = 6.28318530718
_ARM_JOINTS = [
    ("joint1", "link_base", "link1", (0, 0, 0.267), (0, 0, 0), -_TURN, _TURN, 50.0),
    ("joint2", "link1", "link2", (0, 0, 0), (-1.5708, 0, 0), -2.059, 2.0944, 50.0),
    ("joint3", "link2", "link3", (0.0535, -0.2845, 0), (0, 0, 0), -3.927, 0.19198, 32.0),
    ("joint4", "link3", "link4", (0.0775, 0.3425, 0), (-1.5708, 0, 0), -_TURN, _TURN, 32.0),
    ("joint5", "link4", "link5", (0, 0, 0), (1.5708, 0, 0), -1.69297, 3.14159265359, 32.0),
    ("joint6", "link5", "link6", (0.076, 0.097, 0), (-1.5708, 0, 0), -_TURN, _TURN, 20.0),
]
_ARM_MASSES = {
    "link_base": 2.7,
    "link1": 2.16,
    "link2": 1.71,
    "link3": 1.384,
    "link4": 1.115,
    "link5": 1.275,
    "link6": 0.1096,
}


@dataclass(frozen=True)
class _Cylinder:
    """A cylinder from point ``a`` to point ``b`` (link frame, metres) of ``radius``."""

    a: tuple
    b: tuple
    radius: float


@dataclass(frozen=True)
class _Box:
    """A box of ``size`` (x, y, z) centred at ``center`` (link frame), axes along the link's."""

    center: tuple
    size: tuple


def _rpy_z_to(direction: np.ndarray) -> tuple[float, float, float]:
    """URDF (roll, pitch, yaw) that turns the local z axis onto ``direction``."""
    d = direction / np.linalg.norm(direction)
    pitch = math.atan2(math.hypot(d[0], d[1]), d[2])
    yaw = math.atan2(d[1], d[0]) if math.hypot(d[0], d[1]) > 1e-12 else 0.0
    return 0.0, pitch, yaw


def _fmt(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _shape_xml(shape, material: str, rgba: str) -> str:
    if isinstance(shape, _Cylinder):
        a, b = np.asarray(shape.a, float), np.asarray(shape.b, float)
        origin = f'<origin xyz="{_fmt((a + b) / 2)}" rpy="{_fmt(_rpy_z_to(b - a))}"/>'
        geom = f'<cylinder radius="{shape.radius:.6g}" length="{np.linalg.norm(b - a):.6g}"/>'
    else:
        origin = f'<origin xyz="{_fmt(shape.center)}" rpy="0 0 0"/>'
        geom = f'<box size="{_fmt(shape.size)}"/>'
    return (
        f"    <visual>{origin}<geometry>{geom}</geometry>"
        f'<material name="{material}"><color rgba="{rgba}"/></material></visual>\n'
        f"    <collision>{origin}<geometry>{geom}</geometry></collision>\n"
    )


def _link_xml(name: str, shapes, mass: float, rgba: str) -> str:
    # Inertial frame = link frame, so pybullet's link "COM" pose is the URDF link frame.
    i = 1e-3 * max(mass, 0.01)
    body = "".join(_shape_xml(s, f"{name}_color", rgba) for s in shapes)
    return (
        f'  <link name="{name}">\n{body}'
        f'    <inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="{mass:.6g}"/>'
        f'<inertia ixx="{i:.3g}" ixy="0" ixz="0" iyy="{i:.3g}" iyz="0" izz="{i:.3g}"/>'
        f"</inertial>\n  </link>\n"
    )


def _link_shapes() -> dict[str, list]:
    """Collision/visual primitives per link, in each link's own frame (see the module doc)."""
    return {
        # Base housing: the real base is about 0.13 m across; joint 1 sits at z = 0.267.
        "link_base": [_Cylinder((0, 0, 0), (0, 0, 0.16), 0.065)],
        # Column up to the shoulder, and the shoulder housing along the joint-2 axis (link1 y).
        "link1": [
            _Cylinder((0, 0, -0.105), (0, 0, 0.0), 0.06),
            _Cylinder((0, -0.065, 0), (0, 0.065, 0), 0.06),
        ],
        # Upper arm shoulder → elbow, and the elbow housing along joint 3's axis (z).
        "link2": [
            _Cylinder((0, 0, 0), (0.0535, -0.2845, 0), 0.045),
            _Cylinder((0.0535, -0.2845, -0.055), (0.0535, -0.2845, 0.055), 0.05),
        ],
        # Elbow offset, then the forearm tube along joint 4's axis (link3 y) up to the wrist.
        "link3": [
            _Cylinder((0, 0, 0), (0.0775, 0, 0), 0.045),
            _Cylinder((0.0775, 0.0, 0), (0.0775, 0.29, 0), 0.042),
        ],
        # Wrist housing of joint 5 (axis = link4 −y), centred on the wrist point.
        "link4": [_Cylinder((0, -0.05, 0), (0, 0.05, 0), 0.042)],
        # Wrist offset (x) and the joint-6 housing up to the flange (link5 y).
        "link5": [
            _Cylinder((0, 0, 0), (0.076, 0, 0), 0.035),
            _Cylinder((0.076, 0.0, 0), (0.076, 0.09, 0), 0.035),
        ],
        # Flange disc and the hand's mounting bracket up to the tilt knuckle.
        "link6": [_Cylinder((0, 0, -0.01), (0, 0, HAND_PIVOT_FROM_FLANGE - 0.015), 0.032)],
        # Tilt knuckle (along y), a stem, and the cross bar that carries the cups and camera.
        "hand": [
            _Cylinder((0, -0.02, 0), (0, 0.02, 0), 0.015),
            _Cylinder((0, 0, 0), (0, 0, CAMERA_FROM_PIVOT - 0.05), 0.012),
            _Box((0, 0, CAMERA_FROM_PIVOT - 0.045), (0.05, 2 * CUP_OFFSET + 0.02, 0.02)),
        ],
        # SR300-like bar, long along camera x, from the cross bar to the optical centre.
        "camera": [_Box((0, 0, -0.0175), (0.11, 0.02, 0.035))],
    }


def _cup_shapes() -> list:
    """One cup in its own frame (origin at the lip centre, z = camera z)."""
    rod_start = -(CUP_TIP_Z + 0.035)  # the cross bar's front face is at camera z = −0.035
    return [
        _Cylinder((0, 0, rod_start), (0, 0, -CUP_PAD_LENGTH), CUP_ROD_RADIUS),
        _Cylinder((0, 0, -CUP_PAD_LENGTH), (0, 0, 0), CUP_DIAMETER / 2),
    ]


def _joint_xml(
    name, kind, parent, child, xyz, rpy, lower=None, upper=None, effort=None, axis=(0, 0, 1)
) -> str:
    s = (
        f'  <joint name="{name}" type="{kind}">\n    <parent link="{parent}"/>\n'
        f'    <child link="{child}"/>\n    <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>\n'
    )
    if kind == "revolute":
        s += (
            f'    <axis xyz="{_fmt(axis)}"/>\n'
            f'    <limit effort="{effort:.6g}" lower="{lower:.12g}" upper="{upper:.12g}" '
            f'velocity="3.14"/>\n    <dynamics damping="1.0" friction="1.0"/>\n'
        )
    return s + "  </joint>\n"


def build_urdf_xml() -> str:
    """The URDF text of the whole robot (see the module docstring for the frames)."""
    shapes = _link_shapes()
    colors = {
        "link_base": "0.28 0.52 0.92 1",
        "link1": "0.85 0.19 0.21 1",
        "link2": "0.95 0.76 0.05 1",
        "link3": "0.28 0.52 0.92 1",
        "link4": "0.23 0.72 0.32 1",
        "link5": "0.85 0.19 0.21 1",
        "link6": "0.753 0.753 0.753 1",
        "hand": "0.3 0.3 0.3 1",
        "camera": "0.1 0.1 0.1 1",
    }
    out = [
        '<?xml version="1.0" encoding="utf-8"?>\n',
        "<!-- Generated by pipeline/robot/urdf_builder.py; edit that file, not this one.\n"
        "     xArm6 kinematics (pybullet_data xarm/xarm6_robot.urdf) with primitive geometry,\n"
        "     a 1-DoF hand tilt (joint7), an OpenCV-frame camera link and two suction cups\n"
        "     (cup_left at camera y = -0.035 m, cup_right at +0.035 m, lips at camera z = "
        f"{CUP_TIP_Z} m). -->\n",
        '<robot name="binpick_robot">\n',
    ]
    for name in ["link_base", "link1", "link2", "link3", "link4", "link5", "link6"]:
        out.append(_link_xml(name, shapes[name], _ARM_MASSES[name], colors[name]))
    out.append(_link_xml("hand", shapes["hand"], 0.3, colors["hand"]))
    out.append(_link_xml("camera", shapes["camera"], 0.1, colors["camera"]))
    for cup in ("cup_left", "cup_right"):
        out.append(_link_xml(cup, _cup_shapes(), 0.02, "0.9 0.9 0.9 1"))
    for name, parent, child, xyz, rpy, lo, hi, effort in _ARM_JOINTS:
        out.append(_joint_xml(name, "revolute", parent, child, xyz, rpy, lo, hi, effort))
    out.append(
        _joint_xml(
            "joint7",
            "revolute",
            "link6",
            "hand",
            (0, 0, HAND_PIVOT_FROM_FLANGE),
            (0, 0, 0),
            -HAND_TILT_LIMIT,
            HAND_TILT_LIMIT,
            10.0,
            axis=(0, 1, 0),
        )
    )
    out.append(
        _joint_xml("camera_joint", "fixed", "hand", "camera", (0, 0, CAMERA_FROM_PIVOT), (0, 0, 0))
    )
    for cup, y in (("cup_left", -CUP_OFFSET), ("cup_right", CUP_OFFSET)):
        out.append(_joint_xml(f"{cup}_joint", "fixed", "camera", cup, (0, y, CUP_TIP_Z), (0, 0, 0)))
    out.append("</robot>\n")
    return "".join(out)


def write_urdf(path: Path = URDF_PATH) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(build_urdf_xml())
    return path


if __name__ == "__main__":
    print(write_urdf())
