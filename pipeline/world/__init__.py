"""The simulated world of the closed loop: everything a real cell has in physics, not in software.

The world side holds the physics (pybullet: the bin, the heap, the robot's body), renders the
hand camera and runs the sensor model, executes the robot's joint commands, judges what happens
(contacts that stop the robot, the seal and hold of the cups, a box lifted or dropped), counts
the boxes and keeps the trial's books. It hands the robot side (``pipeline.controller``) one
observation per camera frame and nothing else. Ground truth (body ids, box poses, sizes,
masses) stays here, with the judge of outcomes and the oracle planner, the one planner that
plans from it.

* :mod:`pipeline.world.cell`: the bin, the heap and the robot in one pybullet world; the hand
  camera's observations.
* :mod:`pipeline.world.suction`: a suction gripper that can fail like a real one (seal test by
  ray casts from the cups' lips, wrench test of the held box, a force-limited fixed constraint).
* :mod:`pipeline.world.trial`: one attempt and one trial (the paper's protocol, Sec. 6), the
  robot side deciding and the world executing and judging.
* :mod:`pipeline.world.oracle`: the labels on the home image as a planner (ground truth).
* :mod:`pipeline.world.diagnosis`: why a trial ended "no grasp", from the truth.
"""
