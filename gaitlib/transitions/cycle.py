"""The collector's per-world cycle, all worlds at once: reset with a source gait, run it, switch, run the horizon,
label the outcome (see :mod:`gaitlib.transitions.collector` for the protocol)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from gaitlib.envs import ImitationEnv
from gaitlib.training.policy import GaitPolicy, per_gait
from gaitlib.transitions import schema
from gaitlib.transitions.explicit import EXPLICIT_DIM, explicit_state

if TYPE_CHECKING:
    from gaitlib.transitions.collector import CollectConfig

__all__ = ["SwitchCycles"]


class SwitchCycles:
    """The vectorized per-world cycle: reset with a source gait, run, switch, run the horizon, label."""

    def __init__(
        self,
        env: ImitationEnv,
        policies: list[GaitPolicy],
        *,
        pairs: list[tuple[int, int]],
        counts: np.ndarray,
        cfg: CollectConfig,
        latent_dim: int,
        seed: int,
        first_chunk: int,
    ) -> None:
        self.env = env
        self.policies = policies
        self._chunk = first_chunk
        self.source_falls = 0
        self.world_steps = 0
        """Control steps taken over all worlds."""
        dev, n = env.device, env.num_envs
        self._chain = cfg.chain
        self._dev = dev
        self._gen = torch.Generator().manual_seed(seed)
        self._pair_source = torch.tensor([m for m, _ in pairs], device=dev)
        self._pair_dest = torch.tensor([d for _, d in pairs], device=dev)
        self._warmup = round(cfg.warmup_s / env.dt)
        self._extra = round(cfg.source_extra_s / env.dt)
        self._horizon = max(1, round(cfg.horizon_s / env.dt))
        self._pair = torch.zeros(n, dtype=torch.long, device=dev)  # index into the pairs of each world's cycle
        self._load = torch.tensor([int(counts[m, d]) for m, d in pairs])  # samples per pair, written or under way
        self._in_horizon = torch.zeros(n, dtype=torch.bool, device=dev)
        self._steps_left = torch.zeros(n, dtype=torch.long, device=dev)  # in the current stage, control steps
        # What is known of each world's sample at the switch, and the largest push since.
        self._source = torch.zeros(n, dtype=torch.long, device=dev)
        self._latent = torch.zeros(n, latent_dim, device=dev)
        self._explicit = torch.zeros(n, EXPLICIT_DIM, device=dev)
        self._phase_source = torch.zeros(n, device=dev)
        self._phase_dest = torch.zeros(n, device=dev)
        self._value_source = torch.zeros(n, device=dev)
        self._value_dest = torch.zeros(n, device=dev)
        self._switch_time = torch.zeros(n, device=dev)
        self._max_push = torch.zeros(n, device=dev)
        self._done: list[schema.TransitionBatch] = []
        self.pending = 0
        """Finished samples not yet taken."""
        self._restart(torch.arange(n, device=dev), new_pair=True)

    def step(self) -> None:
        """Advance every world one control step and move its state machine on."""
        env = self.env
        _, _, dones, extras = env.step(per_gait(self.policies, env.gait, env.get_observations()))
        fell = dones & ~extras["time_outs"]
        self._steps_left -= 1
        push = env.push_force.norm(dim=1)
        self._max_push = torch.where(self._in_horizon, self._max_push, torch.maximum(self._max_push, push))
        finished = self._in_horizon & (fell | (self._steps_left <= 0))
        source_fell = ~self._in_horizon & fell
        due = ~self._in_horizon & ~fell & (self._steps_left <= 0)
        self.world_steps += env.num_envs
        if finished.any():
            self._finish(finished.nonzero().squeeze(1), ~fell)
        self.source_falls += int(source_fell.sum())
        chained = finished & ~fell & self._chain
        if chained.any():
            chained = self._continue(chained.nonzero().squeeze(1))
        restart = finished & ~chained
        if restart.any():
            self._restart(restart.nonzero().squeeze(1), new_pair=True)
        if source_fell.any():
            self._restart(source_fell.nonzero().squeeze(1), new_pair=False)
        if due.any():
            self._switch(due.nonzero().squeeze(1))

    def take(self, *, limit: int) -> schema.TransitionBatch | None:
        """The finished samples in order (at most ``limit``; the rest are dropped) as the next chunk of the file
        (``chunk`` set, counting on from ``first_chunk``); ``None`` if there are none."""
        done, self._done, self.pending = self._done, [], 0
        if not done:
            return None
        batch = schema.TransitionBatch.concatenate(done).select(slice(0, limit))
        batch.chunk[:] = self._chunk
        self._chunk += 1
        return batch

    def _restart(self, ids: torch.Tensor, *, new_pair: bool) -> None:
        k = len(ids)
        if new_pair:
            self._pair[ids] = self._least_sampled(k).to(self._dev)
        self.env.reset_worlds(ids, gait=self._pair_source[self._pair[ids]])
        self.env.enable_pushes(ids, True)
        self._max_push[ids] = 0.0
        self._in_horizon[ids] = False
        extra = torch.randint(self._extra + 1, (k,), generator=self._gen).to(self._dev)
        self._steps_left[ids] = self._warmup + extra

    def _continue(self, ids: torch.Tensor) -> torch.Tensor:
        """Chain worlds ``ids`` (just through a successful switch) into a new cycle from the gait they now run, where
        that keeps the pairs balanced; returns the (N,) mask of the worlds chained."""
        gait = self.env.gait[ids].cpu()
        candidates = self._pair_source.cpu().unsqueeze(0) == gait.unsqueeze(1)  # (k, P)
        keys = torch.where(candidates, self._load.unsqueeze(0).float(), torch.inf)
        keys = keys + 0.5 * torch.rand(keys.shape, generator=self._gen)
        best_key, best = keys.min(dim=1)
        ok = best_key <= float(self._load.min() + self.env.num_envs)
        chosen = torch.zeros(self.env.num_envs, dtype=torch.bool)
        chosen[ids.cpu()[ok]] = True
        ids, best = ids[ok.to(ids.device)], best[ok]
        self._pair[ids] = best.to(self._dev)
        self._load += torch.bincount(best, minlength=len(self._load))
        self.env.enable_pushes(ids, True)
        self._max_push[ids] = 0.0
        self._in_horizon[ids] = False
        self._steps_left[ids] = torch.randint(self._extra + 1, (len(ids),), generator=self._gen).to(self._dev)
        return chosen.to(self._dev)

    def _least_sampled(self, k: int) -> torch.Tensor:
        """(k,) pairs for k new cycles, filling up the least-sampled pairs first (ties at random)."""
        levels = self._load.unsqueeze(1) + torch.arange(k).unsqueeze(0)  # (P, k): load after 1..k more cycles
        keys = levels + 0.5 * torch.rand(levels.shape, generator=self._gen)
        chosen = torch.topk(keys.flatten(), k, largest=False).indices // k
        self._load += torch.bincount(chosen, minlength=len(self._load))
        return chosen[torch.randperm(k, generator=self._gen)]

    def _switch(self, ids: torch.Tensor) -> None:
        env = self.env
        before = env.get_observations()[ids]
        source = env.gait[ids]
        self._source[ids] = source
        self._latent[ids] = per_gait(self.policies, source, before, method="latent")
        self._value_source[ids] = per_gait(self.policies, source, before, method="value")
        self._explicit[ids] = explicit_state(before["policy"])
        self._phase_source[ids] = env.phase[ids]
        self._switch_time[ids] = env.episode_length_buf[ids].float() * env.dt
        dest = self._pair_dest[self._pair[ids]]
        phase = torch.rand(len(ids), generator=self._gen).to(self._dev)
        env.switch(ids, dest, phase)
        env.enable_pushes(ids, False)
        self._phase_dest[ids] = phase
        self._value_dest[ids] = per_gait(self.policies, dest, env.get_observations()[ids], method="value")
        self._in_horizon[ids] = True
        self._steps_left[ids] = self._horizon

    def _finish(self, ids: torch.Tensor, alive: torch.Tensor) -> None:
        def rows(t: torch.Tensor) -> np.ndarray:
            return t[ids].cpu().numpy()

        self._done.append(
            schema.TransitionBatch(
                source=rows(self._source),
                dest=rows(self._pair_dest[self._pair]),
                latent=rows(self._latent),
                phase_source=rows(self._phase_source),
                phase_dest=rows(self._phase_dest),
                explicit=rows(self._explicit),
                value_source=rows(self._value_source),
                value_dest=rows(self._value_dest),
                push_force=rows(self._max_push),
                success=rows(alive),
                switch_time=rows(self._switch_time),
                world=ids.cpu().numpy(),
                chunk=np.zeros(len(ids)),
                fall_after=np.where(rows(alive), np.inf, rows(self._horizon - self._steps_left) * self.env.dt),
            )
        )
        self.pending += len(ids)
