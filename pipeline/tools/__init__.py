"""Developer tools beside the pipeline: benchmarks (``bench``, ``bench_gpu``, ``bench_ood``),
the artifact viewer and verifier (``view``, ``verify``) and the reproducibility check
(``repro_check``). Each runs as ``python -m pipeline.tools.<name>``; no stage imports a tool.
"""
