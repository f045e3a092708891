"""What a grasp is, shared by every user below the stages: the grasp classes and surface type
(``types``), planar surfaces in a depth image (``surfaces``: paper Sec. 4.3, Figs. 4b–4c), the
two-cup hand's pattern rule (``hand``: Figs. 5–6) and the suction cup's physical model
(``suction``: cup settings and the hold test). Labelling, the planners, the servo's descriptor,
the robot's run-time check and the simulated gripper all import them from here.
"""
