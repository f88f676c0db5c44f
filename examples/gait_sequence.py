"""Drive one robot through a sequence of gaits with the meta-controller (paper Algorithm 1) and the shipped
library (or $GAITLIB_LIBRARY): each gait is requested once the previous one has run --hold seconds after its
switch, and the strategy picks the moment. What ``gaitlib run --from trot --to stand,pace,trot`` does, from Python.

    python examples/gait_sequence.py
    python examples/gait_sequence.py --strategy tmt --sequence trot,pace,stand --video sequence.mp4
    python examples/gait_sequence.py --sequence stand,walk,pace,bound,trot,pronk,stand
    python examples/gait_sequence.py --sequence trot,pace --routed   # trot, stand, pace
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gaitlib.defaults import DEFAULT_STRATEGY
from gaitlib.meta import load_switching
from gaitlib.meta.episode import run_episode
from gaitlib.meta.trace_plot import plot_trace
from gaitlib.strategies.routes import load_routes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None, help="default: $GAITLIB_LIBRARY or the shipped one")
    parser.add_argument("--sequence", default="trot,stand,pace,trot,stand")
    parser.add_argument("--strategy", default=DEFAULT_STRATEGY)
    parser.add_argument("--hold", type=float, default=2.5, help="time in a gait after its switch, s")
    parser.add_argument("--plot", default="sequence.png")
    parser.add_argument("--video", default=None, help="also render an MP4 (pip install -e '.[video]')")
    parser.add_argument("--routed", action="store_true", help="through other gaits where the route table says")
    args = parser.parse_args()

    first, *rest = args.sequence.split(",")
    setup = load_switching(args.library)
    if args.routed:  # the library's route table, measured by `gaitlib routes`
        rest = load_routes(setup.resources.library, setup.gaits).expand(first, tuple(rest))
    trace = run_episode(setup, source=first, dests=rest, strategy=args.strategy, request_s=1.5, hold_s=args.hold)
    for request_s, event in zip(trace.requests_s, trace.switches, strict=False):
        how = "forced" if event.forced else "random" if event.score != event.score else f"score {event.score:.3f}"
        print(
            f"{request_s:6.2f} s  request {setup.gaits[event.dest]}; switched from {setup.gaits[event.source]} at "
            f"{event.step * trace.dt:.2f} s, phase {event.phase:.2f} ({how})"
        )
    print(f"plot: {plot_trace(trace, args.plot)}")
    if args.video:
        from gaitlib.meta.video import render_trace

        render_trace(trace, args.video)
        print(f"video: {args.video}")
    if not trace.stayed_up:
        raise SystemExit(f"the robot fell at {trace.fell_s:.2f} s")
    print(f"done: {len(trace.switches)} switches in {trace.time_s[-1]:.1f} s, the robot stayed up")


if __name__ == "__main__":
    main()
