"""A Dex-Net-style suction grasp planner, built from Dex-Net's published method (paper Sec. 6,
8.1.1, Table 2, Fig. 10): candidate sampling on the depth image (``sampling``), the
cross-entropy method policy (``cem``), an analytic depth-only quality (``quality``), the suction
contact model that labels candidates in simulation (``contact``) and the GQ-CNN trained on those
labels (``gqcnn``). ``planner.DexNetPlanner`` has the same call interface as the project's own
planner. docs/baseline.md gives the facts this follows.
"""
