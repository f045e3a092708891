"""The training stage's numerical settings (pipeline/planner/numerics.py) and the GPU bench's
answer on a machine without CUDA."""

import os

import pytest
import torch

from pipeline.planner.numerics import CUBLAS_WORKSPACE_CONFIG, set_training_numerics


@pytest.fixture
def restore_torch_flags():
    saved = (
        torch.backends.cudnn.allow_tf32,
        torch.backends.cuda.matmul.allow_tf32,
        torch.are_deterministic_algorithms_enabled(),
        torch.is_deterministic_algorithms_warn_only_enabled(),
    )
    yield
    torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = saved[:2]
    torch.use_deterministic_algorithms(saved[2], warn_only=saved[3])


@pytest.mark.parametrize("device_type, warn_only", [("cpu", False), ("cuda", True)])
def test_training_numerics_are_deterministic_float32(
    device_type, warn_only, monkeypatch, restore_torch_flags
):
    monkeypatch.delenv("CUBLAS_WORKSPACE_CONFIG", raising=False)
    torch.backends.cudnn.allow_tf32 = True  # PyTorch's default
    torch.backends.cuda.matmul.allow_tf32 = True
    set_training_numerics(device_type)
    assert torch.backends.cudnn.allow_tf32 is False
    assert torch.backends.cuda.matmul.allow_tf32 is False
    assert torch.are_deterministic_algorithms_enabled()
    assert torch.is_deterministic_algorithms_warn_only_enabled() is warn_only
    assert os.environ.get("CUBLAS_WORKSPACE_CONFIG") == (
        CUBLAS_WORKSPACE_CONFIG if device_type == "cuda" else None
    )


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the answer without a GPU")
def test_gpu_bench_says_it_needs_cuda(capsys):
    from pipeline.tools.bench_gpu import main

    assert main([]) == 2
    assert "no CUDA device" in capsys.readouterr().err
