"""Drive one robot through a sequence of gaits with the meta-controller (paper Algorithm 1) and the shipped
library: each gait is requested once the previous switch has settled, and the strategy picks the moment.

    python examples/gait_sequence.py
    python examples/gait_sequence.py --strategy tmt --sequence trot,pace,stand
"""

from __future__ import annotations

import argparse

import torch

from gaitlib.defaults import DEFAULT_STRATEGY
from gaitlib.meta import load_switching
from gaitlib.sim import make_backend


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequence", default="trot,stand,pace,trot,stand")
    parser.add_argument("--strategy", default=DEFAULT_STRATEGY)
    parser.add_argument("--settle", type=float, default=1.5, help="time in a gait before the next request, s")
    args = parser.parse_args()

    setup = load_switching(None)  # the shipped library (or $GAITLIB_LIBRARY)
    sequence = [setup.gait_index(g) for g in args.sequence.split(",")]
    sim = make_backend("auto", num_worlds=1)
    try:
        env = setup.make_env(sim, seed=1)
        env.reset_worlds(torch.tensor([0]), gait=torch.tensor([sequence[0]]))
        controller = setup.controller(env, args.strategy)
        settle = round(args.settle / env.dt)
        since_switch, step = 0, 0
        for target in sequence[1:]:
            while since_switch < settle or env.gait[0] != target:
                if since_switch == settle and controller.queued[0] < 0:
                    controller.request([0], target)
                    print(f"{step * env.dt:6.2f} s  request {setup.gaits[target]}")
                result = controller.step()
                step, since_switch = step + 1, since_switch + 1
                for event in result.events:
                    how = "forced" if event.forced else f"score {event.score:.3f}"
                    print(
                        f"{step * env.dt:6.2f} s  switched {setup.gaits[event.source]} -> {setup.gaits[event.dest]}"
                        f" at phase {event.phase:.2f} after {event.wait_s:.2f} s ({how})"
                    )
                    since_switch = 0
                if result.fell[0]:
                    raise SystemExit(f"{step * env.dt:6.2f} s  the robot fell")
        print(f"done: {len(sequence) - 1} switches in {step * env.dt:.1f} s, the robot stayed up")
    finally:
        sim.close()


if __name__ == "__main__":
    main()
