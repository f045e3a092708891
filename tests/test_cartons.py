"""The carton distribution (pipeline/simulation/cartons.py) and the heaps drawn from it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest
from omegaconf import OmegaConf

from pipeline.runtime.cli import compose
from pipeline.simulation.cartons import check_cartons, draw_carton, is_held_out


@pytest.fixture(scope="module")
def cfg():
    return OmegaConf.to_object(compose("generate", ["experiment=smoke", "boxes=cartons"]))


def test_held_out_by_hand():
    """(0.10, 0.065, 0.040) held out with margin 0.15: each sorted edge within 15 % of it.
    0.11 is 10 % off the long edge: held out, in any axis order. 0.12 is 20 % off: not."""
    tea = [[0.10, 0.065, 0.040]]
    assert is_held_out([0.040, 0.11, 0.065], tea, 0.15)
    assert not is_held_out([0.12, 0.065, 0.040], tea, 0.15)
    assert not is_held_out([0.10, 0.065, 0.040], [], 0.15)


def test_draws_stay_in_their_ranges_and_under_the_payload(cfg):
    c = cfg.boxes.cartons
    rng = np.random.default_rng(0)
    draws = [draw_carton(c, rng) for _ in range(3000)]
    for d in draws:
        L, M, S = np.sort(d.size)[::-1]
        assert c.long_edge[0] <= L <= c.long_edge[1]
        assert c.middle_ratio[0] * L - 1e-12 <= M <= c.middle_ratio[1] * L + 1e-12
        assert S >= c.min_edge and S <= c.short_ratio[1] * M + 1e-12
        assert d.mass <= c.max_mass + 1e-12
        assert c.density[0] - 1e-9 <= d.density <= c.density[1] + 1e-9
        assert not is_held_out(d.size, c.held_out, c.held_out_margin)
    masses = np.array([d.mass for d in draws])
    # boxes too heavy for one cup (about half the payload at best) are part of the distribution
    assert (masses > 0.5 * c.max_mass).mean() > 0.02
    assert c.max_mass == cfg.hand.payload_kg


def test_every_unseen_size_is_held_out(cfg):
    """The unseen-size sets stay outside the training distribution: every size of
    conf/boxes/unseen.yaml and every non-paper type of the closed-loop boxes is held out."""
    c = cfg.boxes.cartons
    unseen = OmegaConf.to_object(compose("generate", ["experiment=smoke", "boxes=unseen"]))
    sizes = [t.size for t in unseen.boxes.types]
    paper = [t.size for t in cfg.boxes.types]
    sizes += [t.size for t in cfg.eval_boxes.types if t.size not in paper]
    assert len(sizes) == 11
    for s in sizes:
        assert is_held_out(s, c.held_out, c.held_out_margin), s
    for s in paper:  # the paper's three sizes are not carved out
        assert not is_held_out(s, c.held_out, c.held_out_margin), s


@pytest.mark.parametrize(
    "change, key",
    [
        (dict(long_edge=[0.2, 0.1]), "long_edge"),
        (dict(short_ratio=[0.5, 1.5]), "short_ratio"),
        (dict(max_mass=0.0), "max_mass"),
    ],
)
def test_bad_distribution_is_named(cfg, change, key):
    with pytest.raises(ValueError, match=key):
        check_cartons(dataclasses.replace(cfg.boxes.cartons, **change))


def test_impossible_distribution_says_so(cfg):
    c = dataclasses.replace(cfg.boxes.cartons, density=[1e6, 2e6])  # every box too heavy
    with pytest.raises(ValueError, match="no carton drawn"):
        draw_carton(c, np.random.default_rng(0))


def test_carton_heap_bodies_have_their_drawn_size_and_mass(cfg):
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import drop_heap

    client = p.connect(p.DIRECT)
    try:
        build_cell(client, cfg.bin, cfg.physics)
        heap = drop_heap(
            client, np.random.default_rng(5), cfg.boxes, cfg.bin, cfg.physics, cartons=True
        )
        assert heap.boxes
        for box in heap.boxes:
            assert box.type_index == len(cfg.boxes.types)
            shape = p.getCollisionShapeData(box.body_id, -1, physicsClientId=client)[0]
            assert np.allclose(shape[3], box.size, atol=1e-6)
            mass = p.getDynamicsInfo(box.body_id, -1, physicsClientId=client)[0]
            assert mass == pytest.approx(box.mass)
            assert box.mass <= cfg.hand.payload_kg
        with pytest.raises(ValueError, match="boxes.cartons is not set"):
            drop_heap(
                client,
                np.random.default_rng(5),
                dataclasses.replace(cfg.boxes, cartons=None),
                cfg.bin,
                cfg.physics,
                cartons=True,
            )
    finally:
        p.disconnect(client)


def test_generated_cartons_in_train_exact_types_in_test(tmp_path):
    """boxes=cartons: the train split's boxes are cartons (type index len(types), their mass
    stored), the test split keeps the paper's exact sizes with density x volume."""
    from pipeline.dataset import SceneDataset
    from pipeline.stages.generate import generate

    cfg = compose(
        "generate",
        [
            "experiment=smoke",
            "boxes=cartons",
            f"paths.root={tmp_path}",
            "generate.num_scenes=2",
            "generate.num_val_scenes=1",
            "generate.num_test_scenes=2",
            "generate.scenes_per_shard=2",
            "generate.workers=1",
            "logging.progress=false",
        ],
    )
    out = generate(cfg)
    train, test = SceneDataset(out, "train"), SceneDataset(out, "test")
    boxes = [b for i in range(len(train)) for b in train[i].boxes]
    assert boxes and all(b.type_name == "carton" and b.mass > 0 for b in boxes)
    types = {t.name: t.size for t in OmegaConf.to_object(cfg).boxes.types}
    for i in range(len(test)):
        for b in test[i].boxes:
            assert np.allclose(b.size, types[b.type_name])
            assert b.mass == pytest.approx(400.0 * np.prod(b.size))
    # the report's box-type table names the cartons' type without a size
    from pipeline.report.dataset import box_types_table, dataset_stats

    rows = {r[0]: r for r in box_types_table(dataset_stats(out)).rows}
    val = SceneDataset(out, "val")
    cartons = len(boxes) + sum(len(val[i].boxes) for i in range(len(val)))
    assert rows["carton"][1] == "drawn per box (boxes.cartons)" and rows["carton"][2] == cartons


def test_heaviest_mass_by_hand(cfg):
    """Density 100-700 kg/m³, max_mass 1.7 kg: a 10 cm cube (1 l) weighs at most 0.7 kg; a
    20 x 15 x 10 cm carton (3 l) would weigh 2.1 kg at 700 and is capped at the payload."""
    from pipeline.simulation.cartons import heaviest_mass

    c = cfg.boxes.cartons
    assert (list(c.density), c.max_mass) == ([100.0, 700.0], 1.7)
    assert heaviest_mass(c, [0.1, 0.1, 0.1]) == pytest.approx(0.7)
    assert heaviest_mass(c, [0.2, 0.15, 0.1]) == pytest.approx(1.7)


def test_hold_mass_heaviest_weighs_drawn_cartons_only(cfg):
    """label.hold_mass=heaviest: a drawn carton of 12 x 10 x 5 cm (0.6 l) is weighed at
    700 × 0.0006 = 0.42 kg, whatever it drew; a box of a fixed set (no mass) is left alone;
    own leaves every box as it is; a box set without cartons is refused, with the fix named."""
    from pipeline.dataset.scenes import Box
    from pipeline.stages.label import weighed_for_hold

    eye = np.eye(4)
    carton = Box(1, -1, "carton", np.array([0.12, 0.10, 0.05]), eye, eye, mass=0.1)
    paper = Box(2, 0, "medium", np.array([0.145, 0.092, 0.052]), eye, eye)
    scene = dataclasses.make_dataclass("S", [("boxes", list)])([carton, paper])
    heavy = dataclasses.replace(cfg, label=dataclasses.replace(cfg.label, hold_mass="heaviest"))
    out = weighed_for_hold(scene, heavy)
    assert out.boxes[0].mass == pytest.approx(0.42) and out.boxes[1].mass is None
    assert scene.boxes[0].mass == 0.1  # the scene itself is not changed
    assert weighed_for_hold(scene, cfg) is scene  # own, the default
    paper_cfg = OmegaConf.to_object(
        compose("label", ["experiment=smoke", "label.hold_mass=heaviest"])
    )
    with pytest.raises(ValueError, match="use boxes=cartons"):
        weighed_for_hold(scene, paper_cfg)
    bad = dataclasses.replace(cfg, label=dataclasses.replace(cfg.label, hold_mass="light"))
    with pytest.raises(ValueError, match="choose from"):
        weighed_for_hold(scene, bad)
