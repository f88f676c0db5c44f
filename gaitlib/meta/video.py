"""Rendering a run to video with MuJoCo's offscreen renderer, headless through EGL or OSMesa.

MuJoCo picks its OpenGL platform (``MUJOCO_GL``) when it is imported, and gaitlib has imported it long before a
video is asked for; so the frames are rendered in a child process (``python -m gaitlib.meta.video``) started with
the first platform that works: the user's ``MUJOCO_GL`` if set, else ``egl``, then ``osmesa``. The video is
written with imageio (``pip install 'gaitlib[video]'``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from gaitlib.atomic import atomic_path
from gaitlib.errors import GaitlibError

__all__ = ["PLATFORMS", "render_trace", "render_video"]

PLATFORMS = ("egl", "osmesa")
"""Headless OpenGL platforms tried, in order, when ``MUJOCO_GL`` is not set."""
_SIZE = (480, 640)  # height, width in pixels


class _RenderFailed(Exception):
    """The rendering child process failed (its last line of stderr)."""


def render_video(qpos: np.ndarray, path: Path, *, fps: float, model_xml: Path) -> Path:
    """Render the (T, nq) generalized positions with a camera following the trunk into the video ``path``."""
    try:
        import imageio  # noqa: F401
    except ImportError:
        raise GaitlibError("--video needs imageio and imageio-ffmpeg: pip install 'gaitlib[video]'") from None
    path = Path(path)
    platforms = [os.environ["MUJOCO_GL"]] if os.environ.get("MUJOCO_GL") else list(PLATFORMS)
    errors = []
    with tempfile.TemporaryDirectory() as scratch:
        frames = Path(scratch) / "qpos.npy"
        np.save(frames, qpos)
        for platform in platforms:
            try:
                with atomic_path(path) as tmp:
                    command = [sys.executable, "-m", __name__, str(model_xml), str(frames), str(tmp), str(fps)]
                    env = os.environ | {"MUJOCO_GL": platform}
                    done = subprocess.run(command, env=env, capture_output=True, text=True)
                    if done.returncode != 0:
                        raise _RenderFailed((done.stderr.strip().splitlines() or ["failed"])[-1])
                return path
            except _RenderFailed as failed:
                errors.append(f"{platform}: {failed}")
    raise GaitlibError(
        "no headless OpenGL for --video (" + "; ".join(errors) + "); install EGL or OSMesa drivers "
        "(e.g. libegl1, libosmesa6) or set MUJOCO_GL"
    )


def render_trace(trace, path: Path) -> Path:
    """Render a :class:`~gaitlib.meta.episode.RunTrace` of the A1 into the video ``path``, in real time."""
    from gaitlib.robots import get_robot

    return render_video(trace.qpos, path, fps=1.0 / trace.dt, model_xml=get_robot("a1").mjcf_path)


def _render(model_xml: str, frames: str, out: str, fps: float) -> None:
    import imageio
    import mujoco

    model = mujoco.MjModel.from_xml_path(model_xml)
    data = mujoco.MjData(model)
    camera = mujoco.MjvCamera()
    camera.distance, camera.elevation, camera.azimuth = 1.6, -20.0, 120.0
    height, width = _SIZE
    model.vis.global_.offwidth, model.vis.global_.offheight = max(width, 640), max(height, 480)
    with mujoco.Renderer(model, height, width) as renderer, imageio.get_writer(out, fps=fps, format="FFMPEG") as writer:
        for qpos in np.load(frames):
            data.qpos[:] = qpos
            mujoco.mj_forward(model, data)
            camera.lookat[:] = data.qpos[:3]
            renderer.update_scene(data, camera)
            writer.append_data(renderer.render())


if __name__ == "__main__":
    _render(sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4]))
