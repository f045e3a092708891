"""Automatic labelling (paper Sec. 4.3, Figs. 4b–4f, 5, 6): one scene's grasp-point labels and
the robot-level check of a grasp; surfaces and the hand-level rule are in ``pipeline.grasping``."""
