"""The grasp planner (paper Sec. 4.1–4.2): DCNN, its grid targets and loss, decoding, ranking."""

from pipeline.planner.decode import GraspPrediction, decode_output
from pipeline.planner.loss import LossConfig, focal_terms, grasp_loss
from pipeline.planner.network import (
    GraspNet,
    NetworkConfig,
    conv_layers,
    count_flops,
    count_parameters,
    split_output,
)
from pipeline.planner.ranking import (
    GraspCandidate,
    RankingConfig,
    graspability,
    inclination,
    rank_grasps,
    surface_normal,
)
from pipeline.planner.targets import EMPTY, decode_points, encode, stack_targets

__all__ = [
    "EMPTY",
    "GraspCandidate",
    "GraspNet",
    "GraspPrediction",
    "LossConfig",
    "NetworkConfig",
    "RankingConfig",
    "conv_layers",
    "count_flops",
    "count_parameters",
    "decode_output",
    "decode_points",
    "encode",
    "focal_terms",
    "grasp_loss",
    "graspability",
    "inclination",
    "rank_grasps",
    "split_output",
    "stack_targets",
    "surface_normal",
]
