"""The static picking cell: what the robot knows of its workplace before it sees anything.

The ground and the bin (``pipeline.cell.bin``), built from ``conf/bin/`` into any pybullet
client: the simulated world (``pipeline.simulation``, ``pipeline.world``) builds its physics on
them, and the robot side (``pipeline.controller``) builds its own collision model of the cell
from the same description, as a real cell's software holds a CAD model of its bin. Nothing here
knows a box.
"""
