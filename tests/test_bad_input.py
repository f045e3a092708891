"""Bad depth images and bad model files at the three entry points: the DCNN planner
(``Planner.plan``/``predict``/``load``), the Dex-Net planner (``DexNetPlanner.plan``/``run_cem``,
``load_gqcnn``) and the surface descriptor (``describe_surface``).

Contract (``pipeline.camera.depth_input``): a wrong shape/ndim/dtype raises our
``DepthImageError`` (a ``ValueError``) before any library call; NaN, ±inf, ≤ 0 and implausible
depths are no data; the result is then a documented one: a planner returns candidates only at
pixels with valid depth, or ``[]`` with ``last_reason`` in its ``NO_GRASP_REASONS``; the
descriptor returns (features, "") or (None, reason in ``NO_SURFACE_REASONS``).

Scenes: a floor plus random level boxes (rectangles of constant depth), then corrupted with
random mixes of bad values and holes; built with numpy from hypothesis-drawn parameters so a
416 × 416 image costs nothing to draw and failures shrink to the fewest boxes/bad values.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from conftest import default_config
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pipeline.camera.depth_input import MAX_DEPTH_M, MIN_DEPTH_M, DepthImageError, check_depth_image
from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.dexnet.cem import CEMConfig
from pipeline.dexnet.gqcnn import GQCNN, CropConfig, GQCNNConfig
from pipeline.dexnet.planner import NO_GRASP_REASONS as DEX_REASONS
from pipeline.dexnet.planner import DexNetPlanner, Workspace, load_gqcnn
from pipeline.dexnet.quality import PlanarityConfig
from pipeline.dexnet.sampling import SamplerConfig
from pipeline.planner.network import GraspNet, NetworkConfig
from pipeline.planner.normalisation import Normalisation
from pipeline.planner.planner import NO_GRASP_REASONS as DCNN_REASONS
from pipeline.planner.planner import ModelFileError, Planner
from pipeline.planner.ranking import RankingConfig
from pipeline.servo.descriptor import NO_SURFACE_REASONS, DescriptorConfig, describe_surface

SETTINGS = settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

FLOOR = 0.625  # camera height above the bin floor (conf/camera/sr300.yaml)
D_GROUND = 0.645  # + floor thickness
SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
SMALL = Intrinsics(32, 32, 40.0, 40.0, 15.5, 15.5)  # Dex-Net: ~1.2 cm/px at 0.5 m
MID = Intrinsics(48, 48, 60.0, 60.0, 23.5, 23.5)  # descriptor
# conf/servo/'s descriptor, its window-depth tolerance and normal tracking off
DESCRIPTOR = default_config(DescriptorConfig, window_tolerance_depth=0.0, track_normal_deg=0.0)

BAD_VALUES = [
    np.nan,
    np.inf,
    -np.inf,
    0.0,
    -0.5,
    -1e30,
    1e-30,
    0.01,
    50.0,
    1e30,
    float(np.finfo(np.float32).max),
    1e300,
]


def valid_mask(image: np.ndarray) -> np.ndarray:
    """Pixels with a plausible depth, computed from the caller's image independently of the
    validator (float64, so float32 overflow of 1e300 counts as invalid as it should)."""
    with np.errstate(invalid="ignore", over="ignore"):
        x = np.asarray(image, np.float64)
        return (
            np.isfinite(x)
            & (x >= MIN_DEPTH_M)
            & (x <= MAX_DEPTH_M)
            & np.isfinite(np.asarray(image).astype(np.float32))
        )


@st.composite
def depth_scenes(draw, intr: Intrinsics):
    """A corrupted depth image (H, W) in one of float16/32/64."""
    H, W = intr.height, intr.width
    seed = draw(st.integers(0, 2**32 - 1))
    base = draw(st.sampled_from(["boxes", "sparse", "noise", "floor"]))
    n_boxes = draw(st.integers(0, 4))
    bad_frac = draw(st.sampled_from([0.0, 0.001, 0.05, 0.3, 0.7, 0.95, 1.0]))
    bad = draw(st.lists(st.sampled_from(BAD_VALUES), min_size=1, max_size=4))
    n_holes = draw(st.integers(0, 3))
    dtype = draw(st.sampled_from([np.float64, np.float32, np.float16]))
    rng = np.random.default_rng(seed)
    d = np.full((H, W), FLOOR)
    if base == "sparse":  # a few isolated pixels of data
        d[:] = 0.0
        k = int(rng.integers(1, 20))
        d.flat[rng.integers(0, H * W, k)] = rng.uniform(0.4, 0.6, k)
    elif base == "noise":
        d = rng.uniform(0.3, 0.65, (H, W))
    if base in ("boxes", "noise"):
        for _ in range(n_boxes):
            v0, u0 = rng.integers(0, H), rng.integers(0, W)
            h, w = rng.integers(2, H // 2 + 3), rng.integers(2, W // 2 + 3)
            d[v0 : v0 + h, u0 : u0 + w] = rng.uniform(0.4, 0.6)
    m = rng.random((H, W)) < bad_frac
    d[m] = rng.choice(np.array(bad), int(m.sum()))
    for _ in range(n_holes):
        v0, u0 = rng.integers(0, H), rng.integers(0, W)
        s = int(rng.integers(1, H // 4 + 2))
        d[v0 : v0 + s, u0 : u0 + s] = rng.choice(np.array(bad))
    with np.errstate(over="ignore"):
        return d.astype(dtype)


# ---------------------------------------------------------------------------------------------
# Planners under test.


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """One intra-op thread: on a busy 2-core machine torch's thread pool makes the 416 × 416
    forward ~10× slower (1.3 s instead of 0.13 s measured)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def dcnn_planner(firing: bool) -> Planner:
    """An untrained width-1/16 DCNN. ``firing``: class biases raised and output weights scaled
    so that (almost) every cell predicts R/L/B with spread-out offsets: candidates everywhere,
    near holes and edges too; else the initial class prior (no cell above th = 0.5)."""
    torch.manual_seed(0)
    net = GraspNet(default_config(NetworkConfig, width=0.0625))
    if firing:
        with torch.no_grad():
            net.out.weight.mul_(200.0)
            net.out.bias[2:5] = 4.0
            net.out.bias[5] = -4.0  # NG
    return Planner(
        net,
        Normalisation(D_GROUND, 0.1, 0.5),
        default_config(RankingConfig, d_ground=D_GROUND, threshold=0.5),
    )


@pytest.fixture(scope="module")
def firing():
    return dcnn_planner(True)


@pytest.fixture(scope="module")
def quiet():
    return dcnn_planner(False)


def tiny_gqcnn() -> GQCNN:
    torch.manual_seed(0)
    return GQCNN(GQCNNConfig(crop_size=8, width=2, fc=8)).eval()


def dexnet_planners(cem: CEMConfig | None = None, half: float = 0.3) -> list[DexNetPlanner]:
    """Planarity and (untrained) GQ-CNN planners on SMALL images; ``half``: the bin's inner
    half-extent, m (0.3: the whole image is inside the bin)."""
    ws = Workspace(half, half, 0.005, camera_pose_above_bin(FLOOR))
    sampler = default_config(SamplerConfig, border_px=2)
    cem = cem or default_config(
        CEMConfig, num_seed_samples=16, num_gmm_samples=8, num_iters=1, max_resamples=3
    )
    crop = default_config(CropConfig, window_px=8, size=8, d_ground=D_GROUND)
    return [
        DexNetPlanner("planarity", ws, sampler, cem, default_config(PlanarityConfig)),
        DexNetPlanner(
            "gqcnn", ws, sampler, cem, default_config(PlanarityConfig), crop, tiny_gqcnn()
        ),
    ]


@pytest.fixture(scope="module")
def dexnets():
    return dexnet_planners()


def assert_dcnn_result(planner: Planner, image: np.ndarray, out) -> None:
    ok = valid_mask(image)
    H, W = image.shape
    for c in out:
        u, v = int(np.clip(round(c.u), 0, W - 1)), int(np.clip(round(c.v), 0, H - 1))
        assert ok[v, u], f"candidate at ({c.u}, {c.v}) on a pixel without valid depth"
        assert np.isfinite([c.score, c.depth, c.phi, *c.normal_cam]).all()
        assert MIN_DEPTH_M <= c.depth <= MAX_DEPTH_M
    assert (planner.last_reason == "") == bool(out)
    if not out:
        assert planner.last_reason in DCNN_REASONS


def assert_dex_result(planner: DexNetPlanner, image: np.ndarray, out) -> None:
    ok = valid_mask(image)
    assert len(out) <= 1
    for g in out:
        assert ok[int(g.v), int(g.u)], f"grasp at ({g.u}, {g.v}) on a pixel without valid depth"
        assert np.isfinite([g.score, g.depth, g.angle, *g.point_cam, *g.normal_cam]).all()
        # the grasp's own pixel (valid, so finite): casting the whole image would overflow
        assert g.depth == pytest.approx(float(np.float32(np.asarray(image)[int(g.v), int(g.u)])))
    assert (planner.last_reason == "") == bool(out)
    if not out:
        assert planner.last_reason in DEX_REASONS


def assert_descriptor_result(image: np.ndarray, result) -> None:
    features, reason = result
    if features is None:
        assert reason in NO_SURFACE_REASONS
        return
    assert reason == ""
    ok = valid_mask(image)
    assert features.region.shape == image.shape and not (features.region & ~ok).any()
    assert features.num_pixels == int(features.region.sum())
    for a in (
        features.center_px,
        features.center_cam,
        features.normal_cam,
        features.plane,
        features.long_axis_cam,
        features.short_axis_cam,
        features.warped_long,
        features.warped_short,
    ):
        assert np.isfinite(a).all()


def unchanged(before: np.ndarray, after: np.ndarray) -> bool:
    return before.dtype == after.dtype and np.array_equal(before, after, equal_nan=True)


# ---------------------------------------------------------------------------------------------
# The shared validator.


@SETTINGS
@given(
    hnp.arrays(
        st.sampled_from([np.float16, np.float32, np.float64]),
        hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=12),
        elements=st.floats(allow_nan=True, allow_infinity=True, width=16)
        | st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -0.5])
        | st.floats(0.0625, 8.0, width=16),
    )
)
def test_validator_sanitises_to_float32_metres_with_zero_for_no_data(image):
    before = image.copy()
    out = check_depth_image(image)
    assert out.dtype == np.float32 and out.shape == image.shape
    assert unchanged(before, image)  # the caller's array is untouched
    ok = valid_mask(image)
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[~ok], 0.0)
    np.testing.assert_array_equal(out[ok], image[ok].astype(np.float32))
    assert ((out == 0) | ((out >= MIN_DEPTH_M) & (out <= MAX_DEPTH_M))).all()


@pytest.mark.parametrize("dtype", [np.uint16, np.int32, np.int64, np.uint8, bool])
def test_validator_rejects_integer_depth_with_the_conversion(dtype):
    raw = np.full((4, 5), 500, dtype=np.uint16).astype(dtype)
    with pytest.raises(DepthImageError, match=r"depth_m = raw.*\* depth_unit"):
        check_depth_image(raw, (4, 5))


@pytest.mark.parametrize(
    "image",
    [
        np.full((4, 5), 0.5 + 0j),
        np.array([[0.5, None]], dtype=object),
        None,
        "depth",
        [[0.5, 0.5], [0.5]],
    ],
    ids=["complex", "object", "None", "str", "ragged"],
)
def test_validator_rejects_what_is_not_real_depth(image):
    with pytest.raises(DepthImageError, match="float32"):
        check_depth_image(image)


@pytest.mark.parametrize("shape", [(0, 0), (5,), (4, 5, 1), (4, 5, 3), (), (5, 4), (0, 5)])
def test_validator_rejects_wrong_shapes_naming_the_expected_one(shape):
    with pytest.raises(DepthImageError, match=r"\(4, 5\)"):
        check_depth_image(np.full(shape, 0.5), (4, 5))


def test_validator_treats_masked_pixels_as_no_data():
    image = np.ma.masked_array(np.full((3, 3), 0.5), mask=np.eye(3, dtype=bool))
    out = check_depth_image(image)
    np.testing.assert_array_equal(out, np.where(np.eye(3, dtype=bool), 0.0, 0.5).astype(np.float32))


# ---------------------------------------------------------------------------------------------
# Property tests: random mixes of bad values, holes, dtypes.


@SETTINGS
@given(depth_scenes(SR300))
def test_dcnn_plan_never_fails_and_grasps_only_valid_pixels(firing, image):
    before = image.copy()
    out = firing.plan(image, SR300)
    assert unchanged(before, image)
    assert_dcnn_result(firing, image, out)
    event(f"DCNN: {'candidates' if out else firing.last_reason}")


@SETTINGS
@given(depth_scenes(SMALL))
def test_dexnet_plan_never_fails_and_grasps_only_valid_pixels(dexnets, image):
    before = image.copy()
    for planner in dexnets:
        out = planner.plan(image, SMALL)
        assert unchanged(before, image)
        assert_dex_result(planner, image, out)
        event(f"Dex-Net {planner.variant}: {'grasp' if out else planner.last_reason}")


@SETTINGS
@given(depth_scenes(MID), st.tuples(st.floats(-3, 51), st.floats(-3, 51)), st.sampled_from([0, 2]))
def test_descriptor_returns_features_or_a_documented_reason(image, seed, smoothing):
    before = image.copy()
    cfg = dataclasses.replace(DESCRIPTOR, normal_smoothing=smoothing)
    result = describe_surface(image, MID, seed, cfg)
    assert unchanged(before, image)
    assert_descriptor_result(image, result)
    event(f"descriptor: {result[1] or 'features'}")


# ---------------------------------------------------------------------------------------------
# Examples.


def floor_only(intr: Intrinsics) -> np.ndarray:
    """An empty bin: the floor at FLOOR, 1/8 of the image of wall top rims (0.45 m) around
    it and the ground outside (D_GROUND). On SMALL the rims' inner edge is 8 px from the
    centre (x = 8 * 0.45 / 40 = 0.09 m), so a bin of inner half-extent 0.08 m excludes them."""
    H, W = intr.height, intr.width
    d = np.full((H, W), D_GROUND, np.float32)
    b = max(H // 8, 1)
    d[b:-b, b:-b] = 0.45
    d[2 * b : -2 * b, 2 * b : -2 * b] = FLOOR
    return d


def one_pixel(intr: Intrinsics) -> np.ndarray:
    d = np.zeros((intr.height, intr.width), np.float32)
    d[intr.height // 2, intr.width // 2] = 0.5
    return d


EXAMPLES = {
    "all_nan": lambda i: np.full((i.height, i.width), np.nan, np.float32),
    "all_zero": lambda i: np.zeros((i.height, i.width), np.float32),
    "all_negative": lambda i: np.full((i.height, i.width), -0.5),
    "all_inf": lambda i: np.full((i.height, i.width), np.inf),
    "empty_bin": floor_only,
    "one_pixel": one_pixel,
}


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_dcnn_examples(firing, quiet, name):
    image = EXAMPLES[name](SR300)
    for planner in (firing, quiet):
        out = planner.plan(image, SR300)
        assert_dcnn_result(planner, image, out)
        if name in ("all_nan", "all_zero", "all_negative", "all_inf"):
            assert out == [] and planner.last_reason == "no_valid_depth"
        if name == "one_pixel":  # no normal from one pixel: nothing to rank
            assert out == [] and planner.last_reason in ("no_prediction", "no_rankable_candidate")
    assert quiet.plan(floor_only(SR300), SR300) == [] and quiet.last_reason == "no_prediction"
    assert firing.plan(floor_only(SR300), SR300)  # the untrained net "grasps" the floor: valid


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_dexnet_examples(name):
    image = EXAMPLES[name](SMALL)
    for planner in dexnet_planners(half=0.08):
        out = planner.plan(image, SMALL)
        assert out == []
        assert planner.last_reason == {
            "empty_bin": "no_object_pixels",
            "one_pixel": "no_candidates",
        }.get(name, "no_valid_depth")
        res = planner.run_cem(image, SMALL, np.random.default_rng(0))
        assert len(res.best) == 0 and res.best_score == -np.inf


@pytest.mark.parametrize("count", [1, 2, 3, 5])
def test_dexnet_few_acceptable_pixels_with_the_full_cem(count):
    """1–5 acceptable pixels (3 × 3 patches: only the centre has a full Sobel window) with the
    default CEM (200 seeds, 40% mixture components): fewer candidates than the defaults assume,
    the mixture is still fitted on ≥ its number of components, and the grasp is a valid pixel."""
    d = np.zeros((SMALL.height, SMALL.width), np.float32)
    centres = [(6, 6), (6, 20), (20, 6), (20, 20), (13, 13)][:count]  # (v, u)
    for v, u in centres:
        d[v - 1 : v + 2, u - 1 : u + 2] = 0.5
    for planner in dexnet_planners(default_config(CEMConfig)):
        out = planner.plan(d, SMALL)
        assert len(out) == 1 and (int(out[0].v), int(out[0].u)) in centres
        assert_dex_result(planner, d, out)


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_descriptor_examples(name):
    image = EXAMPLES[name](MID)
    result = describe_surface(image, MID, (MID.width // 2, MID.height // 2), DESCRIPTOR)
    assert_descriptor_result(image, result)
    expected = {"empty_bin": "", "one_pixel": "too_few_window_points"}.get(name, "no_depth_at_seed")
    assert result[1] == expected
    if name == "empty_bin":  # the floor is a plane: a surface, at the floor's depth
        assert result[0].center_cam[2] == pytest.approx(FLOOR, abs=1e-4)


@pytest.mark.parametrize("seed", [(np.nan, 3.0), (np.inf, np.inf), (-1e9, 5.0), (4.0, 1e30)])
def test_descriptor_non_finite_or_far_seed(seed):
    image = floor_only(MID)
    assert describe_surface(image, MID, seed, DESCRIPTOR) == (None, "seed_outside_image")


BAD_INPUTS = {  # name → (image maker, message pattern)
    "uint16": (lambda H, W: np.full((H, W), 500, np.uint16), "depth_unit"),
    "int": (lambda H, W: np.full((H, W), 1, np.int64), "depth_unit"),
    "bool": (lambda H, W: np.ones((H, W), bool), "depth_unit"),
    "complex": (lambda H, W: np.full((H, W), 0.5 + 0j), "complex"),
    "object": (lambda H, W: np.full((H, W), 0.5, object), "object"),
    "3d": (lambda H, W: np.full((H, W, 1), 0.5), "3-D"),
    "rgbd": (lambda H, W: np.full((H, W, 4), 0.5), "3-D"),
    "1d": (lambda H, W: np.full(H * W, 0.5), "1-D"),
    "0x0": (lambda H, W: np.zeros((0, 0)), r"\(0, 0\)"),
    "wrong_shape": (lambda H, W: np.full((H, W + 1), 0.5), "expected"),
    "transposed": (lambda H, W: np.full((W + 3, H), 0.5), "expected"),
    "none": (lambda H, W: None, "array"),
}


@pytest.mark.parametrize("name", list(BAD_INPUTS))
def test_bad_shape_or_dtype_raise_our_value_error_everywhere(firing, dexnets, name):
    make, pattern = BAD_INPUTS[name]
    with pytest.raises(DepthImageError, match=pattern):
        firing.plan(make(416, 416), SR300)
    if name not in ("3d", "rgbd"):  # predict takes (..., H, W) batches
        with pytest.raises(DepthImageError, match=pattern):
            firing.predict(make(416, 416))
    for planner in dexnets:
        calls = planner._calls
        with pytest.raises(DepthImageError, match=pattern):
            planner.plan(make(32, 32), SMALL)
        assert planner._calls == calls  # a rejected image does not advance the plan sequence
        with pytest.raises(DepthImageError, match=pattern):
            planner.run_cem(make(32, 32), SMALL, np.random.default_rng(0))
    with pytest.raises(DepthImageError, match=pattern):
        describe_surface(make(48, 48), MID, (24, 24), DESCRIPTOR)
    assert isinstance(DepthImageError("x"), ValueError)


def test_dcnn_plan_rejects_intrinsics_of_another_size(firing):
    with pytest.raises(ValueError, match="intrinsics"):
        firing.plan(floor_only(SR300), SMALL)


def test_dcnn_predict_batches_and_empty_batch(firing):
    assert firing.predict(np.zeros((0, 416, 416), np.float32)).shape == (0, 6, 13, 13)
    batch = np.stack([floor_only(SR300), np.full((416, 416), np.nan, np.float32)])
    out = firing.predict(batch)
    assert out.shape == (2, 6, 13, 13) and torch.isfinite(out).all()


def test_descriptor_rejects_a_malformed_seed():
    with pytest.raises(ValueError, match="seed_uv"):
        describe_surface(floor_only(MID), MID, (1.0, 2.0, 3.0), DESCRIPTOR)


# ---------------------------------------------------------------------------------------------
# Model files.


def model_blob(net: GraspNet, network: dict | None = None) -> dict:
    """As ``pipeline.stages.train`` writes model.pt."""
    return {
        "state_dict": net.state_dict(),
        "network": network or dataclasses.asdict(net.cfg),
        "normalisation": Normalisation(D_GROUND, 0.1, 0.5).as_dict(),
        "ranking": dataclasses.asdict(
            default_config(RankingConfig, d_ground=D_GROUND, threshold=0.5)
        ),
        "classes": ["R", "L", "B", "NG"],
    }


@pytest.fixture(scope="module")
def model_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    torch.manual_seed(0)
    net = GraspNet(default_config(NetworkConfig, width=0.0625))
    small = GraspNet(default_config(NetworkConfig, width=1 / 32))
    sd = net.state_dict()
    blobs = {
        "good": model_blob(net),
        # the smaller network's weights under the config of the wider one
        "width_mismatch": model_blob(small, dataclasses.asdict(net.cfg)),
        "missing_keys": {**model_blob(net), "state_dict": dict(list(sd.items())[3:])},
        "unexpected_keys": {**model_blob(net), "state_dict": {**sd, "head.extra": torch.ones(1)}},
        "no_network_entry": {"state_dict": sd},
        "unknown_config_field": model_blob(net, {**dataclasses.asdict(net.cfg), "depth": 19}),
        "not_a_dict": [1, 2, 3],
    }
    for name, blob in blobs.items():
        torch.save(blob, folder / f"{name}.pt")
    data = (folder / "good.pt").read_bytes()
    (folder / "truncated.pt").write_bytes(data[: len(data) // 2])
    (folder / "garbage.pt").write_bytes(b"this is not a model\n" * 40)
    (folder / "empty.pt").write_bytes(b"")
    return folder


def test_planner_load_of_a_good_file(model_files):
    planner = Planner.load(model_files / "good.pt")
    assert planner.plan(floor_only(SR300), SR300) == []  # the class prior: nothing above th


@pytest.mark.parametrize(
    "name,pattern",
    [
        (
            "width_mismatch",
            r"another shape \(e\.g\. stage16\.0\.conv\.weight: file \(1, 1, 3, 3\), "
            r"network \(2, 1, 3, 3\)",
        ),
        ("missing_keys", "3 tensor\\(s\\) missing"),
        ("unexpected_keys", "unexpected tensor.*head.extra"),
        ("no_network_entry", "lacks network, normalisation, ranking"),
        ("unknown_config_field", "unexpected keyword argument 'depth'"),
        ("not_a_dict", "holds a list"),
        ("truncated", "not a readable"),
        ("garbage", "not a readable"),
        ("empty", "not a readable"),
    ],
)
def test_planner_load_names_file_problem_and_fix(model_files, name, pattern):
    path = model_files / f"{name}.pt"
    with pytest.raises(ModelFileError, match=pattern) as info:
        Planner.load(path)
    message = str(info.value)
    assert str(path) in message and "make train" in message and "models/train/<version>" in message
    assert len(message) < 800  # not torch's wall of text


def test_load_gqcnn_names_file_problem_and_fix(tmp_path, model_files):
    g = tiny_gqcnn()
    crop = dataclasses.asdict(default_config(CropConfig))
    torch.save(
        {
            "network": {"crop_size": 8, "width": 2, "fc": 8},
            "crop": crop,
            "state_dict": g.state_dict(),
        },
        tmp_path / "good.pt",
    )
    net, _ = load_gqcnn(tmp_path / "good.pt")
    assert isinstance(net, GQCNN)
    torch.save(
        {
            "network": {"crop_size": 8, "width": 4, "fc": 8},
            "crop": crop,
            "state_dict": g.state_dict(),
        },
        tmp_path / "width.pt",
    )
    for path, pattern in [
        (tmp_path / "width.pt", "another shape"),
        (model_files / "truncated.pt", "not a readable"),
        (model_files / "garbage.pt", "not a readable"),
        (model_files / "good.pt", "lacks crop"),
    ]:
        with pytest.raises(ModelFileError, match=pattern) as info:
            load_gqcnn(path)
        assert str(path) in str(info.value) and "make baseline" in str(info.value)
