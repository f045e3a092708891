"""The robot model: the one home of the picking robot's geometry and kinematics.

A 6-DoF arm (xArm6 kinematics, standing in for the paper's Toshiba TVL500) plus a 1-DoF
suction hand (paper Sec. 2, Fig. 1): a hand tilt joint, an eye-in-hand depth camera and two
0.018 m vacuum cups 0.035 m either side of the camera along its Y axis (left cup at camera
y = −0.035 m, right cup at +0.035 m). Robot-level labelling (Sec. 4.3: IK, joint-limit and
collision checks of the target hand pose) and the closed-loop picking evaluation (Sec. 5–6)
both use this package, so that they agree on what the robot can reach.

* :mod:`pipeline.robot.urdf_builder`: link and hand geometry; writes ``urdf/binpick_robot.urdf``.
* :mod:`pipeline.robot.model`: :class:`Robot` (FK, IK, collision checks, home pose) and
  :class:`RobotConfig`.
* :mod:`pipeline.robot.target_pose`: the camera's target pose for a surface and grasp pattern.

The package imports nothing itself (pybullet loads with ``model``), so a module that needs only
the geometry (``urdf_builder``, ``target_pose``) does not pull in the simulator.
"""
