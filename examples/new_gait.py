"""Describe a new gait in a few numbers, look at its reference, train it briefly and evaluate it.

    python examples/new_gait.py            # a few minutes on a 2-core CPU
    python examples/new_gait.py --minutes 30

The new gait lands in a library folder of its own (``examples_library/`` here), beside the shipped one and
without touching it. Training longer (``gaitlib train bound --minutes 60``) gives a usable policy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from gaitlib.gaits import GaitDescription, clip_from_description
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait

# A bound: front legs together, hind legs together, half a cycle apart.
BOUND = GaitDescription(
    name="my_bound",
    phase_offsets=(0.0, 0.0, 0.5, 0.5),  # FR, FL, RR, RL touchdown phases, cycles
    duty_factor=0.4,
    stride_frequency=3.0,  # Hz
    forward_speed=0.5,  # m/s
    swing_height=0.07,  # m
    body_height=0.26,  # m
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=3.0)
    parser.add_argument("--library", type=Path, default=Path("examples_library"))
    args = parser.parse_args()

    clip = clip_from_description(BOUND)
    frame = clip.frame(torch.linspace(0, 1, 5)[:-1])
    print(f"{BOUND.name}: period {clip.period:.3f} s, stride {BOUND.stride_length:.3f} m")
    print("contacts (FR, FL, RR, RL) at phases 0, .25, .5, .75:\n", frame.contact.int())

    result = train_gait(
        TrainRequest(
            description=BOUND,
            preset=get_preset("cpu"),
            iterations=10**6,
            time_limit_s=60 * args.minutes,
            library=args.library,
            run_dir=Path("runs") / BOUND.name,
            backend="auto",
            eval_episodes=32,
        ),
        on_iteration=lambda s: print(f"iteration {s.iteration}: reward {s.mean_reward:.3f}", end="\r"),
    )
    e = result.evaluation
    print(f"\nwrote {result.entry}: fall rate {e.fall_rate:.2f}, joint RMSE {e.joint_rmse:.3f} rad")


if __name__ == "__main__":
    main()
