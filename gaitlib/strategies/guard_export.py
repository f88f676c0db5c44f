"""The guard in deployable form (``gaitlib survival export``): what a robot-side loop needs to make the guard's
decision with numpy and onnxruntime alone (``docs/deploying.md``, "The guard on the robot").

Written into one folder:

* ``latent_GAIT.onnx`` per gait: the actor observation (N, its width) to the actor's last hidden layer psi_m (N, L),
  the actor's observation normalizer included (the same observation ``GAIT/policy.onnx`` reads);
* ``survival.onnx``: the survival estimate's inputs (N, G + L + 2, or + 5 with ``imu``: one-hot gait, psi_m, sin
  and cos of 2 pi phase, then the trunk's acceleration in its own frame, gravity left out, m/s^2) to its logit
  (standardization included);
* ``net.onnx``: the transition-net's inputs (N, 2G + L + 2: one-hot m, one-hot n, psi_m, sin and cos of 2 pi phi_n)
  to its logit; a composite net (a library grown by ``gaitlib fit --extend``) is one graph too: every part scores
  every row on its own one-hot blocks (the union's one-hot times a 0/1 matrix), and the row keeps the logit of the
  part that serves its pair (a 0/1 mask from m and n), plus log of the mask's sum, 0 there: a pair no part serves
  scores minus infinity, a switch never made;
* ``guard.json``: the gaits, the policies' identities, the estimate's inputs, horizon, margin, floor, the time from an
  episode's start before which it does not act (``armed_from_s``, s), the catch table (``catch_into``: running
  gait -> sector of ``sectors`` the trunk's acceleration points to -> the gait it is caught into; a gait or sector
  it lacks is never caught; null: the gait offered most) and Platt (a, b) per gait
  (``sigmoid(a * logit + b)``), the net's calibration per ordered pair (``sigmoid(a * logit(clip(sigmoid(z),
  1e-6, 1 - 1e-6)) + b)``), the candidate destination phases, the catch skills (``catchers``: the gaits whose task
  is catch; a catch into one is held until the trunk is calm), when a trunk is calm (``calm``: ``tilt_deg``, deg
  from upright, ``speed_m_s``, horizontal, m/s, ``rate_rad_s``, angular rate norm, rad/s, each a bound it stays
  below, and ``wait_s``, the longest wait for it after the catch, s; :func:`gaitlib.envs.catch.is_calm`), and the
  rule.

An estimate that reads the critic's value is refused in one line: the critic sees privileged simulator quantities a
robot does not have. The explicit state is refused too (export it as a latent-phase estimate: ``--inputs``).
``imu`` is deployable: a robot's IMU gives it (the accelerometer less the gravity its attitude estimate gives, or
the change of the estimated trunk velocity over the control step, divided by the step, in the trunk's frame).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch

from gaitlib.atomic import atomic_path, write_json
from gaitlib.envs.catch import CALM_RATE_RAD_S, CALM_SPEED_M_S, CALM_TILT_DEG, CALM_WAIT_S
from gaitlib.errors import GaitlibError
from gaitlib.evaluation import SECTORS
from gaitlib.strategies.base import phase_grid
from gaitlib.strategies.calibration import Calibration
from gaitlib.strategies.survival import SurvivalEstimate, check_finite
from gaitlib.transition_net.composed import ComposedNet
from gaitlib.transition_net.model import TransitionNet

__all__ = ["DEPLOYABLE_INPUTS", "export_guard"]

DEPLOYABLE_INPUTS = (("latent", "phase"), ("latent", "phase", "imu"))
"""The survival inputs a robot-side loop computes from its own observations and IMU."""
_FORMAT = {"format": "gaitlib.guard_export", "format_version": 5}
"""2: armed_from_s, catch_into; 3: imu, sectors; 4: floor; 5: catchers, calm."""


class _Latent(torch.nn.Module):
    """Actor observation -> psi_m: the actor's normalizer, then its hidden layers."""

    def __init__(self, policy) -> None:
        super().__init__()
        self.normalizer = policy.actor.obs_normalizer
        self.hidden = policy.hidden

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.hidden(self.normalizer(obs))


class _DenseComposite(torch.nn.Module):
    """A :class:`ComposedNet` as one graph of dense operations (module doc): the same logits, no routing by index."""

    def __init__(self, net: ComposedNet) -> None:
        super().__init__()
        self.parts = net.parts
        self.g = len(net.spec.gaits)
        for k, part in enumerate(net.parts):
            encode = torch.zeros(self.g, len(part.spec.gaits))  # the union's one-hot -> the part's
            for i, name in enumerate(part.spec.gaits):
                encode[net.spec.gaits.index(name), i] = 1.0
            self.register_buffer(f"encode_{k}", encode)
            self.register_buffer(f"served_{k}", (net.part_of.cpu() == k).float())  # (G, G): 1 where k serves m -> n

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        g = self.g
        source, dest, rest = features[:, :g], features[:, g:2 * g], features[:, 2 * g:]
        logit, total = torch.zeros_like(features[:, 0]), torch.zeros_like(features[:, 0])
        for k, part in enumerate(self.parts):
            encode, served = getattr(self, f"encode_{k}"), getattr(self, f"served_{k}")
            mask = ((source @ served) * dest).sum(-1)
            logit = logit + mask * part(torch.cat([source @ encode, dest @ encode, rest], dim=-1))
            total = total + mask
        return logit + torch.log(total)


def _export(module: torch.nn.Module, width: int, path: Path, *, inputs: str, output: str) -> None:
    with atomic_path(path) as tmp, warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning)  # the TorchScript exporter, on purpose
        torch.onnx.export(module.eval(), (torch.zeros(1, width),), str(tmp), export_params=True, opset_version=18,
                          input_names=[inputs], output_names=[output],
                          dynamic_axes={inputs: {0: "batch"}, output: {0: "batch"}}, dynamo=False)


def export_guard(folder: Path, *, policies: list, estimate: SurvivalEstimate, net: TransitionNet | ComposedNet,
                 calibration: Calibration, catchers: tuple[str, ...] = ()) -> Path:
    """Write the guard's deployable files into ``folder`` (module doc) for ``policies`` (one
    :class:`~gaitlib.library.policy.GaitPolicy` per gait, in the estimate's order); returns the path of
    ``guard.json``. ``catchers``: the gaits that are catch skills (their task is catch), held after a catch until
    the trunk is calm. An estimate that is not finite, or a catcher that is not one of its gaits, is refused in one
    line before anything is written."""
    check_finite(estimate)
    if tuple(estimate.inputs) not in DEPLOYABLE_INPUTS:
        raise GaitlibError(f"the survival estimate reads {', '.join(estimate.inputs)}; a robot computes only "
                           "latent, phase and imu (the critic's value reads privileged simulator quantities): fit "
                           "it with gaitlib survival fit --inputs latent,phase,imu")
    if net.spec.kind != "latent":
        raise GaitlibError(f"the transition-net reads '{net.spec.kind}' inputs; the exported guard needs a latent net")
    unknown = [g for g in catchers if g not in estimate.gaits]
    if unknown:
        raise GaitlibError(f"catchers {', '.join(unknown)} are not gaits of the survival estimate "
                           f"({', '.join(estimate.gaits)})")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    gaits = estimate.gaits
    for gait, policy in zip(gaits, policies, strict=True):
        _export(_Latent(policy).cpu(), policy.actor_dim, folder / f"latent_{gait}.onnx", inputs="obs", output="latent")

    class _Logit(torch.nn.Module):
        def __init__(self, model: torch.nn.Module) -> None:
            super().__init__()
            self.model = model

        def forward(self, features: torch.Tensor) -> torch.Tensor:
            return self.model(features)

    _export(_Logit(estimate.net).cpu(), int(estimate.net.mean.numel()), folder / "survival.onnx",
            inputs="features", output="logit")
    graph = _DenseComposite(net) if isinstance(net, ComposedNet) else _Logit(net)
    _export(graph.cpu(), net.spec.dim, folder / "net.onnx", inputs="features", output="logit")
    return write_json(folder / "guard.json", _FORMAT | {
        "gaits": list(gaits),
        "library_identities": estimate.identities,
        "inputs": list(estimate.inputs),
        "horizon_s": estimate.horizon_s,
        "margin": estimate.margin,
        "floor": estimate.floor,
        "armed_from_s": estimate.armed_from_s,
        "sectors": list(SECTORS),
        "catch_into": None if estimate.catch_into is None else {
            gaits[g]: {SECTORS[k]: gaits[d] for k, d in enumerate(row.tolist()) if d >= 0}
            for g, row in enumerate(estimate.catch_into) if (row >= 0).any()},
        "survival_platt": {gaits[k]: list(ab) for k, ab in estimate.platt.items()},
        "net_calibration": {f"{gaits[m]}-{gaits[n]}": list(ab) for (m, n), ab in calibration.pairs.items()},
        "candidates": phase_grid().tolist(),
        "catchers": [g for g in gaits if g in catchers],
        "calm": {"tilt_deg": CALM_TILT_DEG, "speed_m_s": CALM_SPEED_M_S, "rate_rad_s": CALM_RATE_RAD_S,
                 "wait_s": CALM_WAIT_S},
        "rule": "from armed_from_s after the start on, catch into the gait whose best calibrated offer (the "
                "catch_into table's gait for the running gait and the sector the trunk's acceleration points to, "
                "where there is a table) beats the calibrated survival estimate by more than the margin, or where "
                "the estimate reads below the floor, at once; then hold it for horizon_s before the requested gait "
                "is switched to again (after a catch into one of catchers, hold it beyond horizon_s until the "
                "trunk is calm: tilted less than calm.tilt_deg from upright, moving horizontally slower than "
                "calm.speed_m_s and turning slower than calm.rate_rad_s, at most calm.wait_s after the catch); "
                "after a switch your switching rule chose, catch for horizon_s only below "
                "the floor",
    }, checksum=True)
