"""Measured figures of the DCNN on a CUDA GPU: planning and training speed, CPU agreement.

    python -m pipeline.tools.bench_gpu [--widths 0.125 1.0] [--steps 20]
    make bench ARGS="--only gpu"

Needs a CUDA device (it says so and exits 2 without one). Prints, for the default network and
the paper's (width 1.0), in one process and one run:

- **planning**: ms per 416 x 416 depth image through the network, batch 1, eval mode, timed
  from the host's float32 image to the host's (2 + C, 13, 13) output (copies and
  synchronisation included); the paper's Table 3 reports 0.034 s of grasp planning per image
  on a GeForce 1080. Decoding and Eq. 7's ranking run on the CPU after it
  (``make bench ARGS="--only planners"`` times the whole planner there).
- **training**: images/s of a training step (forward, focal loss of Eqs. 4-6, backward, Adam),
  batch ``train.batch_size`` (16, the paper's), random depth-like inputs with 10 grasp points
  per image, with the training stage's settings (``planner.numerics.set_training_numerics``:
  deterministic kernels, float32) and, in the same run, with PyTorch's default TF32
  convolutions, and with TF32, cuDNN's autotuner and no determinism (the fastest); the
  projected time of one epoch of the ``paper`` experiment's training images; the peak GPU
  memory of the stage's steps.
- **agreement**: for the same weights and batch, the first step's loss and gradients on the CPU
  (float32) and on CUDA (the stage's float32; TF32) against a float64 CPU reference
  (relative error), and whether two CUDA runs of ``--steps`` steps from the same seed with the
  stage's settings end with bit-identical weights.

It imports only the network, the loss and the targets (no simulator), so it runs on a machine
that has PyTorch and Hydra but not the rest of the project's packages.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import numpy as np
import torch

from pipeline.planner.loss import grasp_loss, loss_config
from pipeline.planner.network import GraspNet, network_config
from pipeline.planner.numerics import set_training_numerics
from pipeline.planner.targets import encode, stack_targets
from pipeline.runtime.cli import compose

MODES = ("stage", "tf32", "autotuned")


def random_training_batch(batch: int, size: int, grid: int, seed: int = 0):
    """Random depth-like inputs (B, 1, S, S), standard normal, and the targets of 10 random
    grasp points of random classes per image (``targets.stack_targets``): what the training
    benchmarks (this module's and ``bench.training_images_per_s``) train on."""
    rng = np.random.default_rng(seed)
    x = torch.from_numpy(rng.normal(0.0, 1.0, (batch, 1, size, size)).astype(np.float32))
    targets = stack_targets(
        [
            encode(rng.uniform(0, size - 1, (10, 2)), rng.integers(0, 4, 10), grid, size)
            for _ in range(batch)
        ]
    )
    return x, targets


def _settings(mode: str) -> None:
    """torch's CUDA flags: the training stage's (``set_training_numerics``: deterministic
    kernels, float32), those with PyTorch's default TF32 convolutions, or the fastest (TF32,
    cuDNN's autotuner, no determinism)."""
    set_training_numerics("cuda")
    torch.backends.cudnn.benchmark = mode == "autotuned"
    torch.backends.cudnn.allow_tf32 = mode != "stage"
    if mode == "autotuned":
        torch.use_deterministic_algorithms(False)


def _sync_ms(fn, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn()
        torch.cuda.synchronize()
        times.append((time.perf_counter() - t0) * 1e3)
    return times


def planning_ms(net_cfg, mode: str, repeats: int = 50) -> float:
    """Median ms of one image through the network on CUDA, host float32 in, host output out,
    with ``mode``'s settings (the closed loop's planner runs with PyTorch's, ``"tf32"``)."""
    _settings(mode)
    torch.manual_seed(0)
    net = GraspNet(net_cfg).cuda().eval()
    x, _ = random_training_batch(1, net_cfg.input_size, net_cfg.grid)

    def plan():
        with torch.inference_mode():
            net(x.cuda()).cpu()

    _sync_ms(plan, 5)  # warm-up: kernels, allocator
    return float(np.median(_sync_ms(plan, repeats)))


def _train_steps(net_cfg, loss_cfg, x, targets, steps: int, lr: float, seed: int = 0):
    """``steps`` Adam steps on one batch from ``seed``; returns (ms per step list, the net)."""
    torch.manual_seed(seed)
    net = GraspNet(net_cfg).cuda().train()
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    xc = x.cuda()

    def step():
        opt.zero_grad(set_to_none=True)
        grasp_loss(net(xc), targets, loss_cfg)["total"].backward()
        opt.step()

    return _sync_ms(step, steps), net


def training_figures(cfg, width: float, steps: int) -> dict[str, float]:
    net_cfg = dataclasses.replace(network_config(cfg), width=width)
    loss_cfg, batch, lr = loss_config(cfg), int(cfg.train.batch_size), float(cfg.train.lr)
    x, targets = random_training_batch(batch, net_cfg.input_size, net_cfg.grid)
    out = {}
    for mode in MODES:
        _settings(mode)
        torch.cuda.reset_peak_memory_stats()
        ms, _ = _train_steps(net_cfg, loss_cfg, x, targets, steps + 3, lr)
        out[f"train_{mode}_images_per_s"] = batch / (float(np.median(ms[3:])) / 1e3)
        if mode == "stage":
            out["train_peak_gpu_mb"] = torch.cuda.max_memory_allocated() / 2**20
    return out


def agreement(cfg, width: float, steps: int) -> dict[str, float]:
    """The first step's loss and gradients on the CPU (float32) and on CUDA (stage settings,
    and PyTorch's default TF32 convolutions) against a float64 CPU reference with the same
    weights and batch; and CUDA against itself after ``steps`` steps with the stage's
    settings."""
    net_cfg = dataclasses.replace(network_config(cfg), width=width)
    loss_cfg, lr = loss_config(cfg), float(cfg.train.lr)
    x, targets = random_training_batch(int(cfg.train.batch_size), net_cfg.input_size, net_cfg.grid)
    torch.manual_seed(0)
    weights = GraspNet(net_cfg).state_dict()

    def first_step(device: str, dtype: torch.dtype):
        net = GraspNet(net_cfg).train()
        net.load_state_dict(weights)
        net = net.to(device, dtype)
        loss = grasp_loss(net(x.to(device, dtype)), targets, loss_cfg)["total"]
        loss.backward()
        grad = torch.cat([p.grad.flatten().cpu().double() for p in net.parameters()])
        return float(loss.detach()), grad

    loss64, grad64 = first_step("cpu", torch.float64)
    out = {"loss_float64_cpu": loss64, "grad_norm_float64_cpu": float(grad64.norm())}
    for key, device, mode in (
        ("cpu", "cpu", "stage"),
        ("cuda_stage", "cuda", "stage"),
        ("cuda_tf32", "cuda", "tf32"),
    ):
        _settings(mode)
        loss, grad = first_step(device, torch.float32)
        out[f"loss_rel_err_{key}"] = abs(loss - loss64) / abs(loss64)
        out[f"grad_rel_err_{key}"] = float((grad - grad64).norm() / grad64.norm())
    _settings("stage")
    final = []
    for _ in range(2):
        _, net = _train_steps(net_cfg, loss_cfg, x, targets, steps, lr)
        final.append(torch.cat([p.detach().flatten().cpu() for p in net.parameters()]))
    out["cuda_runs_max_abs_weight_diff"] = float((final[0] - final[1]).abs().max())
    out["cuda_runs_bit_identical"] = bool(torch.equal(final[0], final[1]))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    widths_help = "network widths (default: the `default` experiment's and 1.0)"
    parser.add_argument("--widths", type=float, nargs="+", help=widths_help)
    parser.add_argument("--steps", type=int, default=20, help="timed training steps per figure")
    args = parser.parse_args(argv)
    if not torch.cuda.is_available():
        print(
            "bench_gpu: torch sees no CUDA device; run it on a machine with an NVIDIA GPU "
            "(the CPU figures are `make bench`'s other groups)",
            file=sys.stderr,
        )
        return 2
    cfg = compose("train", ["experiment=default"])
    paper = compose("train", ["experiment=paper"])
    widths = args.widths or [float(cfg.model.width), float(paper.model.width)]
    paper_train_images = int(paper.generate.num_scenes)
    print(
        f"device: {torch.cuda.get_device_name()}, torch {torch.__version__}, "
        f"CUDA {torch.version.cuda}, cuDNN {torch.backends.cudnn.version()}"
    )
    results: dict = {"device": torch.cuda.get_device_name(), "torch": torch.__version__}
    for width in widths:
        net_cfg = dataclasses.replace(network_config(cfg), width=width)
        params = sum(p.numel() for p in GraspNet(net_cfg).parameters())
        fig = {
            "params_m": params / 1e6,
            "planning_tf32_ms": planning_ms(net_cfg, "tf32"),
            "planning_fp32_ms": planning_ms(net_cfg, "stage"),
        }
        fig.update(training_figures(cfg, width, args.steps))
        fig["paper_epoch_min_stage"] = paper_train_images / fig["train_stage_images_per_s"] / 60
        results[f"width_{width}"] = fig
        print(f"width {width} ({fig['params_m']:.2f} M parameters):")
        print(
            f"  planning, one image through the network: {fig['planning_tf32_ms']:.2f} ms "
            f"(TF32, PyTorch's default), {fig['planning_fp32_ms']:.2f} ms (float32); the "
            "paper's whole planner on a GeForce 1080: 34 ms"
        )
        print(
            f"  training, batch {int(cfg.train.batch_size)}: "
            f"{fig['train_stage_images_per_s']:.0f} images/s with the stage's settings, "
            f"{fig['train_tf32_images_per_s']:.0f} with TF32 convolutions, "
            f"{fig['train_autotuned_images_per_s']:.0f} with TF32 and autotuning (same run); "
            f"peak GPU memory {fig['train_peak_gpu_mb']:.0f} MiB"
        )
        print(
            f"  one epoch of the paper experiment's {paper_train_images} training images: "
            f"{fig['paper_epoch_min_stage']:.2f} min (stage settings, compute only)"
        )
    for width in widths:
        agree = agreement(cfg, width, args.steps)
        results[f"width_{width}"]["agreement"] = agree
        print(
            f"width {width}, one batch, relative error against float64 on the CPU "
            "(loss / gradient):"
        )
        for key, name in (
            ("cpu", "CPU float32"),
            ("cuda_stage", "CUDA, the stage's float32"),
            ("cuda_tf32", "CUDA, TF32 convolutions"),
        ):
            print(
                f"  {name:30s} {agree[f'loss_rel_err_{key}']:.1e} / "
                f"{agree[f'grad_rel_err_{key}']:.1e}"
            )
        print(
            f"  two CUDA runs of {args.steps} steps, same seed, stage settings: "
            f"{'bit-identical' if agree['cuda_runs_bit_identical'] else 'different'} weights "
            f"(max |difference| {agree['cuda_runs_max_abs_weight_diff']:.2e})"
        )
    print(json.dumps(results, default=lambda v: round(v, 4) if isinstance(v, float) else v))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
