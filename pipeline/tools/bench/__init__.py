"""Measured performance figures (``make bench``); prints, never asserts.

Rendering (``--only render``): ms per frame of the ray-cast renderer and of TinyRenderer on the
same frames in one run, the rest check (heaps of 20 boxes that move in one more second, settle
steps), generation scenes/s and the closed loop with each renderer. Generation throughput with 1
and 2 worker processes and the ratio of the stage's per-process rate to a bare pybullet loop doing
the same work (same cell, same trickle drop and rest test, same renderer) measured in the same run.
Labelling throughput with 1 and 2 workers on the generated scenes, and its split between surface
detection and robot checks. Planning time per image of the DCNN (default and paper widths) and of
the Dex-Net-style planner (GQ-CNN and planarity), GQ-CNN training throughput. The closed loop: the
surface descriptor's time per frame, the control loop's rate, simulated seconds per wall second and
the wall time of a 3-box trial. The executors (``executor=local|ray``, ``--only executors``):
overhead per trivial task, Ray's start-up, and generation + labelling throughput with 1 and 2
workers under each. Training memory (``--only training``): peak resident memory of loading an
experiment's splits, reading one epoch of batches from disk and a few training steps of its
network, against what the depth would take held in memory. The sensor model and depth preprocessing
(``--only sensor``): time per image of the SR300 model, hole filling and the median, and what they
do to the depth of the bench's heaps (pixels without data, error against the ideal depth). The DCNN
on a CUDA GPU (``--only gpu``, ``pipeline/tools/bench_gpu.py``): planning time, training images/s
and
agreement with the CPU.

    python -m pipeline.tools.bench [--scenes 60] [--only GROUP] [--experiment paper] [--root <root>]
"""
