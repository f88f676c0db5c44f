"""Can a reference be followed? A centroidal check of a looping clip, before any training.

For every moment of the cycle, the reference's whole-body centre of mass ``c`` and centroidal angular momentum
``L`` (trunk and legs moving as the clip says; MuJoCo's subtree quantities of the A1 model) give the contact force
``F = m (dc'/dt + g e_z)`` the ground must supply and the point it must act at, the zero-moment point (Vukobratovic
and Borovac 2004, "Zero-moment point: thirty five years of its life", Int. J. Humanoid Robotics 1(1)):

    p_x = c_x - (c_z F_x + dL_y/dt) / F_z,    p_y = c_y - (c_z F_y - dL_x/dt) / F_z.

The ground pushes only through the feet the clip has down, so that point must lie in their support set: the
convex hull of the stance feet (a segment for two feet, a point for one, nothing in flight). Where it lies outside,
the nearest point ``q`` of the set is the best the feet can do, and the moment ``F_z (q_y - p_y, p_x - q_x)`` is
missing: it changes the robot's angular momentum away from the reference's, and integrated twice through the
standing robot's composite inertia (periodic, the constant parts chosen to keep it smallest) it is the trunk
rotation the reference does not have, :attr:`ReferenceCheck.tilt_deg`. In flight (or where the reference would
need the feet to pull) the feet give nothing: the missing moment is the reference's whole ``dL/dt``, and the
centre of mass falls freely; over each flight, the height it then gains or loses against the reference, with the
take-off speed chosen to land at the reference's height, is :attr:`ReferenceCheck.flight_drop_m`.

Left out: friction and joint torque limits, and how the missing rotation itself would move the feet. The shipped
gaits' figures, and what they meant in training, are in ``docs/training.md``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from gaitlib.errors import GaitError
from gaitlib.gaits.clip import ReferenceClip
from gaitlib.rotations import yaw_of

__all__ = ["TILT_LIMIT_DEG", "ReferenceCheck", "check_reference", "composite_inertia"]

_GRAVITY = 9.81  # m/s^2: MuJoCo's default gravity, which the A1 model keeps
_SAMPLES = 1024  # points per cycle at which the clip is checked

TILT_LIMIT_DEG = 20.0
"""Missing trunk rotation above which a reference is called unlikely to be followed, degrees: a judgement between
the gaits gaitlib has trained (``docs/training.md``): the trot needs 15 and keeps its speed and heading; the first
library's 0.5 m/s straight pace needed 30, kept its speed but turned about 54 degrees in 20 s; the 0.9 m/s
straight pace needed 80 and ran 17% slow, turned 18 degrees and fell in 8% of its episodes."""


@dataclass(frozen=True, kw_only=True)
class ReferenceCheck:
    """What following a looping reference clip asks of the A1 beyond what its feet can give."""

    gait: str
    """The clip's name."""
    tilt_deg: tuple[float, float]
    """Largest trunk roll and pitch (about the reference trunk's heading x and y axes, which turn with a turning
    gait) the missing moment forces, half the peak-to-peak swing, degrees; the reference itself has none of it."""
    outside_share: float
    """Share of the cycle in which the reference's zero-moment point lies outside its support set, or it has no
    support at all, in [0, 1]."""
    flight_s: float
    """Longest time with no foot down, s."""
    flight_drop_m: float
    """Largest height the centre of mass gains or loses against the reference over one flight (free fall), m."""
    steady_shift_m: float
    """The missing moment averaged over a cycle, as the centre-of-mass shift that would balance it (moment over
    weight), m: a reference leans this much one way on average, which the robot must make up by standing
    differently from it."""

    @property
    def followable(self) -> bool:
        """The missing rotation stays within :data:`TILT_LIMIT_DEG` about both axes."""
        return max(self.tilt_deg) <= TILT_LIMIT_DEG

    def summary(self) -> str:
        """One line: the missing rotation, the flights, the steady lean, and a warning above the limit."""
        roll, pitch = self.tilt_deg
        line = (
            f"reference check of {self.gait}: {roll:.1f} deg of roll and {pitch:.1f} deg of pitch the reference does "
            f"not have (its zero-moment point outside the feet {self.outside_share:.0%} of the cycle); flights up to "
            f"{self.flight_s * 1000:.0f} ms, {self.flight_drop_m * 100:.1f} cm of free fall; steady lean "
            f"{self.steady_shift_m * 100:.1f} cm"
        )
        if not self.followable:
            line += f"; above {TILT_LIMIT_DEG:g} deg: unlikely to be followed (docs/training.md)"
        return line


@functools.lru_cache(maxsize=1)
def composite_inertia() -> tuple[float, np.ndarray]:
    """The A1's total mass, kg, and its (3, 3) rotational inertia about its centre of mass in the standing pose,
    trunk level, kg m^2 (from the MJCF's link masses and inertias; MuJoCo is imported here, on first use)."""
    import mujoco

    from gaitlib.robots.a1.constants import DEFAULT_JOINT_POS, STANDING_HEIGHT

    model = _model()
    data = mujoco.MjData(model)
    data.qpos[:7] = (0.0, 0.0, STANDING_HEIGHT, 1.0, 0.0, 0.0, 0.0)
    data.qpos[7:] = DEFAULT_JOINT_POS
    mujoco.mj_kinematics(model, data)
    masses = model.body_mass[1:]
    positions = data.xipos[1:]
    centre = (masses[:, None] * positions).sum(0) / masses.sum()
    inertia = np.zeros((3, 3))
    for mass, diagonal, rotation, position in zip(
        masses, model.body_inertia[1:], data.ximat[1:].reshape(-1, 3, 3), positions, strict=True
    ):
        r = position - centre
        inertia += rotation @ np.diag(diagonal) @ rotation.T + mass * (r @ r * np.eye(3) - np.outer(r, r))
    return float(masses.sum()), inertia


@functools.lru_cache(maxsize=1)
def _model():
    """The A1's MuJoCo model (imported and loaded on first use)."""
    import mujoco

    from gaitlib.robots.a1.constants import MJCF_PATH

    return mujoco.MjModel.from_xml_path(str(MJCF_PATH))


def _centroidal(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whole-body centre of mass (N, 3), m, its velocity (N, 3), m/s, and the centroidal angular momentum (N, 3),
    N m s, world frame, of the robot in each of a clip's frames (trunk and joints as the frame gives them)."""
    import mujoco
    import torch

    from gaitlib.robots.a1.constants import TRUNK_BODY

    model = _model()
    data = mujoco.MjData(model)
    trunk = model.body(TRUNK_BODY).id  # the root of the robot's tree: its subtree is the whole robot
    qpos = torch.cat([frame.root_pos, frame.root_quat, frame.joint_pos], dim=-1).double().numpy()
    qvel = torch.cat([frame.root_lin_vel, frame.root_ang_vel, frame.joint_vel], dim=-1).double().numpy()
    out = np.zeros((3, len(qpos), 3))
    for n in range(len(qpos)):
        data.qpos[:], data.qvel[:] = qpos[n], qvel[n]
        mujoco.mj_forward(model, data)
        mujoco.mj_subtreeVel(model, data)
        out[:, n] = data.subtree_com[trunk], data.subtree_linvel[trunk], data.subtree_angmom[trunk]
    return out[0], out[1], out[2]


def check_reference(clip: ReferenceClip) -> ReferenceCheck:
    """Check that a looping clip's trunk motion can be carried by its own stance feet (see the module docstring).

    Raises:
        GaitError: the clip does not loop (the check integrates over one cycle).
    """
    if not clip.loop:
        raise GaitError(f"clip '{clip.name}' does not loop: the reference check needs one repeating cycle")
    import torch

    mass, inertia = composite_inertia()
    dt = clip.period / _SAMPLES
    # One sample either side of the cycle, read from the cycles before and after: a turning clip's velocities and
    # momenta turn from cycle to cycle, so the rates at the seam are differences across it, not around one cycle.
    frame = clip.frame(torch.arange(-1, _SAMPLES + 1, dtype=torch.float64) / _SAMPLES)
    feet = frame.foot_pos_world.double().numpy()[1:-1, :, :2]  # (N, 4, 2): on the ground plane
    contact = frame.contact.numpy()[1:-1]
    centre, velocity, momentum = _centroidal(frame)
    acceleration, momentum_rate = _central_rate(velocity, dt), _central_rate(momentum, dt)
    centre, velocity = centre[1:-1], velocity[1:-1]
    force = mass * (acceleration + np.array([0.0, 0.0, _GRAVITY]))
    supported = contact.any(-1) & (force[:, 2] > 0.0)
    lift = np.where(supported, force[:, 2], 1.0)  # N; 1 where unsupported, only to keep the division finite
    zmp = np.stack([
        centre[:, 0] - (centre[:, 2] * force[:, 0] + momentum_rate[:, 1]) / lift,
        centre[:, 1] - (centre[:, 2] * force[:, 1] - momentum_rate[:, 0]) / lift,
    ], axis=-1)
    nearest = _nearest_support_point(zmp, feet, contact)
    gap = nearest - zmp
    missing = np.where(
        supported[:, None], force[:, 2:3] * np.stack([gap[:, 1], -gap[:, 0]], axis=-1), -momentum_rate[:, :2]
    )  # (N, 2) moment about the world x and y axes the feet cannot give, N m
    missing = _heading_frame(missing, yaw_of(frame.root_quat).double().numpy()[1:-1])  # a turning trunk's roll, pitch
    outside = ~supported | (np.linalg.norm(gap, axis=-1) > 1e-9)
    steady = missing.mean(0)
    swing = np.cumsum(missing - steady, axis=0) * dt
    swing -= swing.mean(0)  # the starting angular momentum that keeps the rotation periodic
    rate = np.linalg.solve(inertia[:2, :2], swing.T).T  # rad/s about x and y
    angle = np.cumsum(rate, axis=0) * dt
    tilt = np.degrees((angle.max(0) - angle.min(0)) / 2.0)
    flight_s, drop = _flights(~supported, acceleration[:, 2], dt)
    return ReferenceCheck(
        gait=clip.name,
        tilt_deg=(float(tilt[0]), float(tilt[1])),
        outside_share=float(outside.mean()),
        flight_s=flight_s,
        flight_drop_m=drop,
        steady_shift_m=float(np.linalg.norm(steady) / (mass * _GRAVITY)),
    )


def _heading_frame(vectors: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 2) horizontal world-frame ``vectors`` in the frame turned by ``yaw`` (N,) rad (unchanged for a yaw of 0)."""
    cos, sin = np.cos(yaw), np.sin(yaw)
    return np.stack([cos * vectors[:, 0] + sin * vectors[:, 1], cos * vectors[:, 1] - sin * vectors[:, 0]], axis=-1)


def _central_rate(values: np.ndarray, dt: float) -> np.ndarray:
    """Time derivative (N, ...) of (N + 2, ...) samples ``dt`` apart at their N inner samples, by central
    differences."""
    return (values[2:] - values[:-2]) / (2.0 * dt)


def _nearest_support_point(points: np.ndarray, feet: np.ndarray, contact: np.ndarray) -> np.ndarray:
    """(N, 2) point of each sample's support set (convex hull of its stance feet) nearest to ``points`` (N, 2);
    the point itself where it lies inside, and where there are no stance feet."""
    best = points.copy()
    distance = np.where(contact.any(-1), np.inf, 0.0)
    legs = feet.shape[1]
    for i in range(legs):  # single feet
        candidate = feet[:, i]
        _keep_nearer(best, distance, points, candidate, contact[:, i])
        for j in range(i + 1, legs):  # edges between two stance feet
            a, b = feet[:, i], feet[:, j]
            edge = b - a
            t = np.clip(((points - a) * edge).sum(-1) / np.maximum((edge * edge).sum(-1), 1e-12), 0.0, 1.0)
            _keep_nearer(best, distance, points, a + t[:, None] * edge, contact[:, i] & contact[:, j])
    inside = np.zeros(len(points), dtype=bool)
    for i in range(legs):  # a point inside the hull of up to four feet is inside a triangle of three of them
        for j in range(i + 1, legs):
            for k in range(j + 1, legs):
                down = contact[:, i] & contact[:, j] & contact[:, k]
                inside |= down & _in_triangle(points, feet[:, i], feet[:, j], feet[:, k])
    best[inside] = points[inside]
    return best


def _keep_nearer(best, distance, points, candidate, valid) -> None:
    """Where ``valid`` and ``candidate`` is nearer to ``points`` than ``best``, take it (in place)."""
    d = np.linalg.norm(candidate - points, axis=-1)
    nearer = valid & (d < distance)
    best[nearer] = candidate[nearer]
    distance[nearer] = d[nearer]


def _in_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N,) bool: ``p`` lies in triangle ``abc`` (edges included; a flat triangle holds nothing)."""

    def cross(u, v, w):
        return (v[:, 0] - u[:, 0]) * (w[:, 1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (w[:, 0] - u[:, 0])

    d1, d2, d3 = cross(a, b, p), cross(b, c, p), cross(c, a, p)
    area = cross(a, b, c)
    same = ((d1 >= 0) & (d2 >= 0) & (d3 >= 0)) | ((d1 <= 0) & (d2 <= 0) & (d3 <= 0))
    return same & (np.abs(area) > 1e-12)


def _flights(flying: np.ndarray, vertical_acceleration: np.ndarray, dt: float) -> tuple[float, float]:
    """Longest unsupported stretch of the cycle, s, and the largest height the trunk would gain or lose against the
    reference over one (free fall against the reference's vertical acceleration; the take-off speed chosen so that
    it lands at the reference's height), m."""
    if not flying.any():
        return 0.0, 0.0
    if flying.all():
        raise GaitError("the clip never has a foot down: nothing carries the robot")
    start = int(np.argmin(flying))  # a supported sample: stretches then never wrap around the cycle's end
    flying, error = np.roll(flying, -start), np.roll(-_GRAVITY - vertical_acceleration, -start)
    longest, drop, i = 0, 0.0, 0
    while i < len(flying):
        if not flying[i]:
            i += 1
            continue
        j = i
        while j < len(flying) and flying[j]:
            j += 1
        span = error[i:j]
        height = np.cumsum(np.cumsum(span) * dt) * dt  # from rest at take-off
        times = np.arange(1, j - i + 1) * dt
        height -= times * height[-1] / times[-1]  # the take-off speed that lands at the reference's height
        longest, drop, i = max(longest, j - i), max(drop, float(np.abs(height).max())), j
    return longest * dt, drop
