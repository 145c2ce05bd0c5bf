"""Offscreen rendering of the MuJoCo scene (the MP4 writer it feeds is :mod:`robogest.media.video`).

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` when ``mujoco`` is first imported, and its default (GLFW)
needs a display. On a headless machine we therefore default to EGL *before* importing mujoco; if mujoco was
already imported by someone else with the GLFW default, :func:`make_renderer` swaps in the EGL context
class instead of failing.
"""

from __future__ import annotations

import os
import sys


def _headless() -> bool:
    return sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


if _headless():
    os.environ.setdefault("MUJOCO_GL", "egl")
    if os.environ["MUJOCO_GL"] == "egl":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import functools  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import TYPE_CHECKING  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from robogest.errors import InputError, MissingDependencyError  # noqa: E402
from robogest.fileio import atomic_path  # noqa: E402

if TYPE_CHECKING:
    from robogest.robot.config import RobotConfig

#: Camera for videos: a three-quarter view (strokes towards the listener at +X show); scenes without it use
#: ``FRONT_CAMERA`` (straight on from +X), then MuJoCo's free camera.
CAMERA = "three_quarter"
FRONT_CAMERA = "front"

_INSTALL_HINT = (
    "install an OpenGL backend for headless rendering, e.g. `apt-get install libegl1 libgl1-mesa-dri` (EGL) "
    "or `apt-get install libosmesa6` and set MUJOCO_GL=osmesa; on a desktop set MUJOCO_GL=glfw"
)


def _ensure_headless_context() -> None:
    """If mujoco chose GLFW but there is no display, switch its offscreen context class to EGL."""
    if not _headless() or os.environ.get("MUJOCO_GL", "") not in ("", "glfw", "egl"):
        return
    from mujoco.rendering.classic import gl_context

    ctx = getattr(gl_context, "GLContext", None)
    if ctx is None or "glfw" in getattr(ctx, "__module__", ""):
        try:
            from mujoco.egl import GLContext as EGLContext
        except Exception as e:  # ImportError, OSError (no libEGL), AttributeError
            raise MissingDependencyError(f"no display and EGL is unavailable ({e}); {_INSTALL_HINT}") from None
        gl_context.GLContext = EGLContext


#: Video frame rate: frames at these times of simulated time, whatever the control rate.
VIDEO_FPS = 25
#: Video frame size with a GPU renderer, and with a software one (Mesa llvmpipe), where a quarter of the pixels
#: keeps a video near real time on two cores (1280x720 took 12x the speech's duration there).
FULL_VIDEO_SIZE = (1280, 720)
SOFTWARE_VIDEO_SIZE = (640, 360)
#: Cheaper rendering on a software renderer: no multisampling (2x tripled the cost of a 640x360 frame in llvmpipe)
#: and a shadow map of at most 512 pixels (1024 cost a fifth more, for shadow edges that look the same).
CHEAP_OFFSAMPLES = 0
CHEAP_SHADOWSIZE = 512
_SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer")


@functools.lru_cache(maxsize=1)
def gl_renderer_name() -> str:
    """The offscreen OpenGL renderer's name (``GL_RENDERER``, e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``), read from a
    16x16 context made once per process; "" if the driver does not say."""
    from mujoco.rendering.classic import gl_context

    _ensure_headless_context()
    try:
        ctx = gl_context.GLContext(16, 16)
        ctx.make_current()
        from OpenGL import GL

        name = GL.glGetString(GL.GL_RENDERER)
        ctx.free()
    except Exception as e:  # the GL libraries raise a zoo of types (ImportError, RuntimeError, GLError, ...)
        raise MissingDependencyError(
            f"cannot create an OpenGL context (MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r}): {e}; {_INSTALL_HINT}"
        ) from None
    return name.decode(errors="replace") if isinstance(name, bytes) else str(name or "")


def is_software_renderer(name: str) -> bool:
    """True for a CPU rasterizer (Mesa llvmpipe/softpipe, SwiftShader): frames cost tens of ms per megapixel."""
    return any(s in name.lower() for s in _SOFTWARE_RENDERERS)


@dataclass(frozen=True)
class VideoSettings:
    """How a video will be rendered: frame size, whether cheap options apply (software renderer), and on what."""

    width: int
    height: int
    cheap: bool
    renderer: str

    @property
    def size(self) -> str:
        return f"{self.width}x{self.height}"


def video_settings(width: int | None = None, height: int | None = None) -> VideoSettings:
    """Frame size and render options for a video: ``width`` x ``height`` where given, else :data:`FULL_VIDEO_SIZE`
    with a GPU renderer and :data:`SOFTWARE_VIDEO_SIZE` with a software one; cheap options on a software renderer."""
    name = gl_renderer_name()
    cheap = is_software_renderer(name)
    auto_w, auto_h = SOFTWARE_VIDEO_SIZE if cheap else FULL_VIDEO_SIZE
    width, height = int(width or auto_w), int(height or auto_h)
    _check_size(width, height)
    return VideoSettings(width, height, cheap, name)


def _check_size(width: int, height: int) -> None:
    if width < 16 or height < 16 or width % 2 or height % 2:
        raise InputError(f"video size {width}x{height}: use even sizes of at least 16 pixels (H.264 needs even)")


def make_renderer(model: mujoco.MjModel, width: int, height: int, *, cheap: bool = False) -> mujoco.Renderer:
    """Create an offscreen renderer of ``width`` x ``height`` pixels, or say what to install.

    ``cheap`` (for a software renderer): no multisampling, a shadow map of at most :data:`CHEAP_SHADOWSIZE` pixels
    and no reflections; ``model``'s own settings are left as they were (the GL context copies them when made)."""
    _check_size(width, height)
    # The offscreen buffer must hold the frame; scenes ask for 1280x960, enlarge it for bigger requests.
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    _ensure_headless_context()
    quality = model.vis.quality
    saved = int(quality.offsamples), int(quality.shadowsize)
    if cheap:
        quality.offsamples, quality.shadowsize = CHEAP_OFFSAMPLES, min(saved[1], CHEAP_SHADOWSIZE)
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as e:  # the GL libraries raise a zoo of types (ImportError, RuntimeError, GLError, ...)
        raise MissingDependencyError(
            f"cannot create the MuJoCo renderer (MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r}): {e}; {_INSTALL_HINT}"
        ) from None
    finally:
        quality.offsamples, quality.shadowsize = saved
    if cheap:
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    return renderer


def camera_id(model: mujoco.MjModel, name: str = CAMERA) -> int:
    """Id of camera ``name`` (default the three-quarter view), else of ``front``, else -1 (the free camera)."""
    cam = int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name))
    return cam if cam >= 0 else int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, FRONT_CAMERA))


#: Framing of a scene without a named camera: elevation (degrees; negative looks down) and the room left around the
#: upper body at rest, as a fraction of its larger extent (for gestures: arms raised, a hand to the side).
FRAMING_ELEVATION_DEG = -10.0
FRAMING_PAD = 0.3


def upper_body_points(model: mujoco.MjModel, data: mujoco.MjData, robot: RobotConfig) -> np.ndarray:
    """World positions ``(P, 3)`` of the robot's retargeting sites in ``data`` (head, shoulders, elbows, wrists:
    the upper body a gesture moves), metres."""
    ids = sorted({mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s) for v in robot.retarget for s in v.robot})
    points: np.ndarray = data.site_xpos[[i for i in ids if i >= 0]].copy()
    return points


def framing_camera(
    model: mujoco.MjModel, data: mujoco.MjData, robot: RobotConfig, width: int, height: int
) -> mujoco.MjvCamera:
    """A fixed camera facing the robot's front (+X, looking along -X, slightly down) that frames its upper body in
    ``data`` (:func:`upper_body_points`, with :data:`FRAMING_PAD` of room) in a ``width`` x ``height`` frame."""
    p = upper_body_points(model, data, robot)
    if not len(p):  # no site in the model: the bodies' extent
        p = data.xpos[1:].copy()
    lo, hi = p.min(axis=0), p.max(axis=0)
    pad = FRAMING_PAD * max(float((hi - lo).max()), 0.05)
    half_w, half_h = 0.5 * (hi[1] - lo[1]) + pad, 0.5 * (hi[2] - lo[2]) + pad
    tan_v = np.tan(np.radians(float(model.vis.global_.fovy)) / 2)
    tan_h = tan_v * width / height
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = 0.5 * (lo + hi)
    cam.azimuth, cam.elevation = 180.0, FRAMING_ELEVATION_DEG
    cam.distance = max(half_h / tan_v, half_w / tan_h) + 0.5 * (hi[0] - lo[0]) + pad
    return cam


def video_camera(
    model: mujoco.MjModel, data: mujoco.MjData, robot: RobotConfig, width: int, height: int
) -> int | mujoco.MjvCamera:
    """The scene's video camera (:func:`camera_id`) if it has one, else :func:`framing_camera` (an imported robot's
    MJCF has none)."""
    cam = camera_id(model)
    return cam if cam >= 0 else framing_camera(model, data, robot, width, height)


def render_frame(renderer: mujoco.Renderer, data: mujoco.MjData, camera: int | mujoco.MjvCamera) -> np.ndarray:
    """One RGB frame ``(H, W, 3)`` uint8 of the current state."""
    renderer.update_scene(data, camera=camera)
    rgb: np.ndarray = renderer.render()
    return rgb


def render_png(
    robot: RobotConfig, q_rad: np.ndarray | None, path: str | Path, width: int = 640, height: int = 480
) -> Path:
    """Render the robot at joint angles ``q_rad`` (``(J,)`` rad, YAML joint order; None = rest) to a PNG.

    Parameters
    ----------
    robot : RobotConfig
    q_rad : ndarray [shape=(J,)], radians, or None
    path : str or Path
        Output ``.png``.
    width, height : int
        Image size, pixels.

    Returns
    -------
    Path
        The written file.
    """
    from robogest.backends.mujoco_sim import load_sim_model
    from robogest.media.png import write_png

    sim = load_sim_model(robot)
    q = robot.rest_q_rad if q_rad is None else np.asarray(q_rad, dtype=float)
    if q.shape != (len(robot.joints),):
        raise InputError(f"q_rad has shape {q.shape}; expected ({len(robot.joints)},) for robot {robot.name}")
    data = mujoco.MjData(sim.model)
    data.qpos[sim.qpos_idx] = q
    mujoco.mj_forward(sim.model, data)
    renderer = make_renderer(sim.model, width, height)
    try:
        rgb = render_frame(renderer, data, video_camera(sim.model, data, robot, width, height))
    finally:
        renderer.close()
    path = Path(path)
    with atomic_path(path, ".png") as tmp:
        write_png(tmp, rgb)
    return path
