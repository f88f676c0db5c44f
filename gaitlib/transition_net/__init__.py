"""The transition-net: predicts whether switching from gait m to gait n at destination phase phi_n succeeds, from
the source policy's latent (or, as ablations, the phases or the explicit state). Features, model, balanced
dataset, fitting, its learning curve, storage, and the composite of several nets that a library grown by
``gaitlib fit --extend`` holds."""

from gaitlib.transition_net.composed import ComposedNet
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
from gaitlib.transition_net.storage import (
    NetPart,
    SavedNet,
    load_net,
    load_parts,
    net_metadata,
    read_metadata,
    save_composed,
    save_net,
)

__all__ = [
    "INPUT_KINDS",
    "TEST_FRACTION",
    "BalancedSplit",
    "ComposedNet",
    "CurvePoint",
    "EpochStats",
    "FeatureSpec",
    "FitConfig",
    "FitResult",
    "NetPart",
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
    "load_parts",
    "net_metadata",
    "read_metadata",
    "save_composed",
    "save_net",
]
