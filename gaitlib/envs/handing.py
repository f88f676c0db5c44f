"""Handing a robot over between policies, as :class:`~gaitlib.envs.ImitationEnv`'s methods (a mixin, split from it
for length): what a switch would hand over now (:meth:`HandingOver.handover_states`), continuing from such a recorded
state (:meth:`HandingOver.hand_over`, switch-start and catch training), and the single shoves whose push under way a
recorded state keeps (:meth:`HandingOver.shove`, :meth:`HandingOver.push_under_way`; :mod:`gaitlib.envs.handover`)."""

from __future__ import annotations

import torch

from gaitlib.envs.handover import HandoverStates
from gaitlib.rotations import quat_from_yaw, quat_multiply, quat_rotate, yaw_of
from gaitlib.sim import KinematicState

__all__ = ["HandingOver"]


class HandingOver:
    """The hand-over methods of :class:`~gaitlib.envs.ImitationEnv`, which holds the state they read and write (its
    backend, reference, observation history, last action, PD targets and push schedule)."""

    def handover_states(self, world_ids: torch.Tensor) -> dict[str, torch.Tensor]:
        """What a switch of worlds ``world_ids`` (k,) would hand over now, as the arrays of
        :class:`~gaitlib.envs.handover.HandoverStates` (k rows each; yaw removed, see there)."""
        s, ids = self._state, world_ids
        unturn = quat_from_yaw(-yaw_of(s.root_quat[ids]))
        return {
            "source": self.reference.gait[ids],
            "phase": self.reference.wrapped_phase[ids],
            "root_height": s.root_pos[ids, 2],
            "root_quat": quat_multiply(unturn, s.root_quat[ids]),
            "root_lin_vel": quat_rotate(unturn, s.root_lin_vel[ids]),
            "root_ang_vel": s.root_ang_vel[ids],
            "joint_pos": s.joint_pos[ids],
            "joint_vel": s.joint_vel[ids],
            "history": self._history[ids],
            "last_reading": self._last_reading[ids],
            "action": self._action[ids],
            "targets": self._targets[ids],
        }

    def hand_over(self, world_ids: torch.Tensor, states: HandoverStates, phase: torch.Tensor) -> None:
        """Worlds ``world_ids`` (k,) continue from ``states`` (k rows: another gait's robot, the moment before a
        switch) under their own gait from ``phase`` (k,), exactly as :meth:`switch` hands a robot over: its body,
        velocities, observation history, last action and PD targets still under way are kept, and the reference is
        anchored where it stands and faces. Their dynamics, pushes and episode clock are those of their reset."""
        dev, k = self.device, len(world_ids)

        def tensor(name: str) -> torch.Tensor:
            return torch.as_tensor(getattr(states, name), dtype=torch.float32, device=dev)

        root_pos = torch.zeros(k, 3, device=dev)
        root_pos[:, 2] = tensor("root_height")
        kinematic = KinematicState(
            root_pos=root_pos, root_quat=tensor("root_quat"), root_lin_vel=tensor("root_lin_vel"),
            root_ang_vel=tensor("root_ang_vel"), joint_pos=tensor("joint_pos"), joint_vel=tensor("joint_vel"),
        )
        self.backend.reset(world_ids, kinematic)
        targets = tensor("targets")[:, : self._targets.shape[1]]
        pad = self._targets.shape[1] - targets.shape[1]  # a shorter recorded delay line: the oldest target repeats
        self._targets[world_ids] = torch.cat([targets, targets[:, -1:].expand(-1, pad, -1)], 1) if pad else targets
        self._action[world_ids] = tensor("action")
        self._history[world_ids] = tensor("history")
        self._last_reading[world_ids] = tensor("last_reading")
        if states.push_force is not None:  # the push under way when the state was taken goes on
            self._pushes.hold(world_ids.cpu(), tensor("push_force").cpu(), tensor("push_steps").round().long().cpu())
            self.backend.set_trunk_force(world_ids, self._pushes.force[world_ids.cpu()].to(dev))
        self._state = s = self.backend.state()
        gait = self.reference.gait[world_ids]
        self.reference.start(world_ids, gait, phase.to(dev), s.root_pos[world_ids], s.root_quat[world_ids])
        self._obs = self._observations()

    def shove(self, world_ids: torch.Tensor, force: torch.Tensor, steps: int) -> None:
        """Push worlds ``world_ids`` (k,) with ``force`` (k, 3) N, world frame, through the next ``steps`` control
        steps (a single shove; random pushes keep to their own timers after it)."""
        self._pushes.hold(world_ids.cpu(), force.cpu(), torch.full((len(world_ids),), steps))
        self.backend.set_trunk_force(world_ids, force.to(self.device))

    def push_under_way(self, world_ids: torch.Tensor) -> dict[str, torch.Tensor]:
        """The push on worlds ``world_ids`` (k,) now, as :data:`~gaitlib.envs.handover.PUSH_ARRAYS` (the force in
        the yaw-free frame of :meth:`handover_states`, N; the control steps it still lasts, as floats)."""
        force, steps = self._pushes.under_way(world_ids.cpu())
        unturn = quat_from_yaw(-yaw_of(self._state.root_quat[world_ids]))
        return {"push_force": quat_rotate(unturn, force.to(self.device)), "push_steps": steps.float().to(self.device)}
