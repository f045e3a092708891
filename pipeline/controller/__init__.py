"""The robot side of the closed loop: everything a real cell's computer decides, from what its
camera sees.

The robot gets one observation type (``pipeline.controller.observation.Observation``: the depth
image as the camera delivers it, the intrinsics, the camera pose from its own kinematics and the
joint state) and the static cell model (``pipeline.cell``: ground and bin; its own robot model,
``pipeline.robot``). Planning, choosing a candidate, the run-time check, the retry memory and the
servo see nothing else: no body ids, instance masks, box poses, sizes, masses or hidden geometry.
The simulated world (``pipeline.world``) is on the other side of that fence; an import contract
(``pyproject.toml``, ``[tool.importlinter]``) keeps this package from importing it.
"""
