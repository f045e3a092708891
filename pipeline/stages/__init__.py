"""The pipeline's stages, one module each, in the order ``make reproduce`` runs them.

``generate`` (box heaps and their depth images) → ``label`` (grasp-point labels) → ``train``
(the DCNN) → ``baseline`` (the Dex-Net-style comparison, Table 2) → ``evaluate`` (the closed
loop, Table 3) → ``unseen``, ``ablation``, ``robustness`` (studies that run the stages above
with other settings). The report (``pipeline.report``) reads their artifacts.

Each module holds one pure function ``<stage>(cfg) -> Path`` (a versioned artifact folder) and
a thin Hydra command line: ``python -m pipeline.stages.<stage> [overrides]``. The method lives
in the library packages below; a stage module composes them and writes the artifact.
"""
