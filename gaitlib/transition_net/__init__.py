"""The transition-net: predicts whether switching from gait m to gait n at destination phase phi_n succeeds, from
the source policy's latent (or, as ablations, the phases or the explicit state). Features, model, balanced
dataset, fitting, its learning curve, and storage."""

from gaitlib.transition_net.curve import TEST_FRACTION, CurvePoint, learning_curve
from gaitlib.transition_net.dataset import BalancedSplit, balanced_split
from gaitlib.transition_net.evaluate import evaluate_net
from gaitlib.transition_net.features import (
    INPUT_KINDS,
    FeatureSpec,
    batch_features,
    build_features,
    check_input_kinds,
)
from gaitlib.transition_net.fit import EpochStats, FitConfig, FitResult, fit
from gaitlib.transition_net.model import TransitionNet
from gaitlib.transition_net.storage import SavedNet, load_net, read_metadata, save_net

__all__ = [
    "INPUT_KINDS",
    "TEST_FRACTION",
    "BalancedSplit",
    "CurvePoint",
    "EpochStats",
    "FeatureSpec",
    "FitConfig",
    "FitResult",
    "SavedNet",
    "TransitionNet",
    "balanced_split",
    "batch_features",
    "build_features",
    "check_input_kinds",
    "evaluate_net",
    "fit",
    "learning_curve",
    "load_net",
    "read_metadata",
    "save_net",
]
