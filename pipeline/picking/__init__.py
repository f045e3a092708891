"""Closed-loop picking in simulation: executing a chosen grasp with the robot in pybullet.

* :mod:`pipeline.picking.cell`: the bin, the heap and the robot in one pybullet world; depth
  images from the hand camera.
* :mod:`pipeline.picking.suction`: a suction gripper that can fail like a real one (seal test by
  ray casts from the cups' lips, wrench test of the held box, a force-limited fixed constraint).
* :mod:`pipeline.picking.trial`: one attempt (plan at home, servo, approach, suction, lift,
  place) and one trial (the paper's protocol, Sec. 6).
"""

from pipeline.picking.suction import (PATTERN_CUPS, GraspOutcome, HoldResult, SealResult,
                                      SuctionGripper, hold_test, seal_test)

__all__ = ["PATTERN_CUPS", "GraspOutcome", "HoldResult", "SealResult", "SuctionGripper",
           "hold_test", "seal_test"]
