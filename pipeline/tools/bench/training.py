"""Training figures: memory of loading and training an experiment, training images per second."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np


def _rss_mb() -> float:
    """This process's resident memory now, MB (Linux ``/proc/self/status``)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _training_memory_child(
    experiment: str, root: str | None, steps: int, loader_workers: int, width: float | None
) -> dict:
    """Runs in a fresh process (``training_memory``): the training stage's data path over
    the experiment's latest label artifact, then ``steps`` optimisation steps of its network."""
    import resource

    import torch

    from pipeline.artifacts import load_manifest, resolve_artifact
    from pipeline.dataset.labels import LabelSet
    from pipeline.planner.data import GraspDataset, epoch_batches, make_loader
    from pipeline.planner.distributed import DistContext
    from pipeline.planner.loss import grasp_loss, loss_config
    from pipeline.planner.network import GraspNet, network_config
    from pipeline.planner.normalisation import normalisation
    from pipeline.runtime.cli import compose, data_root

    overrides = [f"experiment={experiment}"] + ([f"paths.root={root}"] if root else [])
    overrides += [f"model.width={width}"] if width is not None else []
    cfg = compose("train", overrides)
    label_dir = resolve_artifact(data_root(cfg), "label", "latest")
    gen_dir = resolve_artifact(
        data_root(cfg), "generate", load_manifest(label_dir)["upstream"]["generate"]
    )
    torch.set_num_threads(int(cfg.train.num_threads))
    out = {"rss_start_mb": _rss_mb()}
    net_cfg, norm = network_config(cfg), normalisation(cfg)
    cache = data_root(cfg) / ".cache" / "depth" / gen_dir.name
    t0 = time.perf_counter()
    sets = {
        s: GraspDataset(
            gen_dir, LabelSet(label_dir, s), s, norm, net_cfg.grid, cfg.hand, cache_dir=cache
        )
        for s in ("train", "val", "test")
    }
    out["load_s"] = time.perf_counter() - t0
    out["rss_after_load_mb"] = _rss_mb()
    train = sets["train"]
    h, w = train.depth.shape
    out["images"] = sum(len(d) for d in sets.values())
    out["in_memory_depth_mb"] = out["images"] * h * w * 2 / 2**20
    batch = int(cfg.train.batch_size)
    batches, _ = epoch_batches(len(train), batch, int(cfg.seed), 0, "none", DistContext())
    t0 = time.perf_counter()
    for _x, _targets in make_loader(train, batches, loader_workers):
        pass
    out["epoch_decode_s"] = time.perf_counter() - t0
    out["decode_images_per_s"] = len(train) / out["epoch_decode_s"]
    out["rss_after_epoch_of_data_mb"] = _rss_mb()
    torch.manual_seed(0)
    net = GraspNet(net_cfg)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    loss_cfg = loss_config(cfg)
    net.train()
    t0 = time.perf_counter()
    for x, targets in make_loader(train, batches[:steps], loader_workers):
        loss = grasp_loss(net(x), targets, loss_cfg)["total"]
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    out["train_images_per_s"] = steps * batch / (time.perf_counter() - t0)
    out["width"] = net_cfg.width
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["peak_rss_loader_worker_mb"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return out


def training_memory(
    experiment: str = "paper",
    root: str | None = None,
    steps: int = 4,
    loader_workers: int = 1,
    width: float | None = None,
) -> dict:
    """Peak memory of training at an experiment's scale (its latest label artifact under
    ``root``), measured in a fresh process: load the splits (label rows in memory, depth
    streamed from the on-disk cache), read one epoch of training batches through the
    DataLoader, then ``steps`` optimisation steps of the experiment's network (batch 16).
    Also the size the depth of all splits would take in memory."""
    import subprocess
    import sys

    code = (
        "import json, sys; from pipeline.tools.bench import _training_memory_child; "
        "print('RESULT ' + json.dumps(_training_memory_child(*json.loads(sys.argv[1]))))"
    )
    args = json.dumps([experiment, root, steps, loader_workers, width])
    proc = subprocess.run([sys.executable, "-c", code, args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"training memory benchmark failed:\n{proc.stderr[-2000:]}")
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def training_images_per_s(
    cfg, width: float, batch: int = 16, steps: int = 4, channels_last: bool = False
) -> float:
    """Training throughput (forward + focal loss + backward + Adam step), CPU, 2 threads, on
    random depth-like inputs with 10 random grasp points per image, in the contiguous or the
    channels-last memory layout (``train.channels_last``); ``cfg``'s network at ``width``."""
    import torch

    from pipeline.planner.loss import grasp_loss, loss_config
    from pipeline.planner.network import GraspNet, network_config
    from pipeline.tools.bench_gpu import random_training_batch

    torch.set_num_threads(2)
    torch.manual_seed(0)
    layout = torch.channels_last if channels_last else torch.contiguous_format
    net_cfg = dataclasses.replace(network_config(cfg), width=width)
    net = GraspNet(net_cfg).train().to(memory_format=layout)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    x, targets = random_training_batch(batch, net_cfg.input_size, net_cfg.grid)
    x = x.to(memory_format=layout)
    times = []
    for _ in range(steps + 1):  # the first step warms up
        t0 = time.perf_counter()
        opt.zero_grad()
        grasp_loss(net(x), targets, loss_config(cfg))["total"].backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    return batch / float(np.median(times[1:]))
