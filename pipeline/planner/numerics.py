"""The numerical settings of training: deterministic kernels and full float32 on every device.

The training stage and ``pipeline.tools.bench_gpu`` (which measures what these settings cost and
what they buy) call ``set_training_numerics``; it is the one place they are written.
"""

from __future__ import annotations

import os

import torch

# cuBLAS needs a fixed workspace to be deterministic (PyTorch's reproducibility notes).
CUBLAS_WORKSPACE_CONFIG = ":4096:8"


def set_training_numerics(device_type: str) -> None:
    """Deterministic algorithms and full-float32 convolutions and matrix products.

    PyTorch runs CUDA convolutions in TF32 by default (10-bit mantissa). For the DCNN that puts
    a training step's gradient about ten times further from a float64 reference than float32
    does, on the CPU or on CUDA (``make bench ARGS="--only gpu"`` measures both, and the speed
    TF32 would gain); the training stage keeps float32 so that a GPU trains with the CPU's
    arithmetic. On CUDA a kernel without a deterministic implementation warns instead of
    failing.

    Args:
        device_type: ``"cpu"`` or ``"cuda"`` (``torch.device.type``).
    """
    if device_type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", CUBLAS_WORKSPACE_CONFIG)
    torch.backends.cudnn.allow_tf32 = False
    torch.backends.cuda.matmul.allow_tf32 = False
    torch.use_deterministic_algorithms(True, warn_only=device_type == "cuda")
