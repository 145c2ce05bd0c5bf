"""MuJoCo backend: the robot's MJCF with position-servo actuators, stepped at the model's own timestep.

* :class:`MujocoBackend` (registered as ``"sim"``) speaks the same :class:`Backend` interface as the servo
  buses, so the one player (:func:`~robogest.backends.player.play`, through the control loop and its online
  limiter) drives the simulator exactly like hardware (``write_goal`` + ``advance``). It can count
  self-contacts, pace itself to the wall clock and call observers after every physics step (video, viewer).
* :func:`simulate` plays a whole :class:`Trajectory` through that player, measures how well the simulated
  servos track it and optionally renders an MP4 (three-quarter camera) with the speech audio muxed in.
"""

from __future__ import annotations

# render first: it picks a headless OpenGL backend before mujoco is imported
from robogest.backends import render as _render  # isort: skip

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from robogest.backends.base import Backend, register_backend
from robogest.backends.sim_report import SimReport, tracking_report
from robogest.errors import BackendError, ConfigError, InputError, MissingDependencyError, SafetyError
from robogest.robot.config import RobotConfig
from robogest.trajectory.types import Trajectory

if TYPE_CHECKING:
    from robogest.backends.recorder import VideoRecorder, ViewerObserver

#: Name of the keyframe every robot model defines at its rest pose.
HOME_KEY = "home"


@dataclass
class SimModel:
    """A compiled robot model with index maps from YAML joint order into MuJoCo arrays.

    Attributes
    ----------
    model : mujoco.MjModel
    qpos_idx : ndarray [shape=(J,)], int
        ``data.qpos[qpos_idx]`` are the joint angles in YAML order.
    dof_idx : ndarray [shape=(J,)], int
        ``data.qvel[dof_idx]`` are the joint velocities.
    act_idx : ndarray [shape=(J,)], int
        ``data.ctrl[act_idx]`` are the position goals.
    robot_geoms : ndarray [shape=(G,)], bool
        Geoms that belong to the robot (not to the world body: floor, desk).
    """

    model: mujoco.MjModel
    qpos_idx: np.ndarray
    dof_idx: np.ndarray
    act_idx: np.ndarray
    robot_geoms: np.ndarray


def load_sim_model(robot: RobotConfig) -> SimModel:
    """Compile ``robot.model`` and check that every YAML joint is a hinge driven by one position servo.

    Raises
    ------
    ConfigError
        The MJCF does not compile, or does not do what the YAML commands
        (:func:`~robogest.robot.problems.sim_mapping_problems`).
    """
    from robogest.robot.mjcf import joint_actuators, load_mjcf
    from robogest.robot.problems import sim_mapping_problems, summary

    where = robot.path or robot.name
    model = load_mjcf(robot)
    problems = sim_mapping_problems(robot, model)
    if problems:  # the simulator would not do what the YAML commands: say what, on one line
        raise ConfigError(f"{where}: the MuJoCo model does not match the robot YAML: {summary(problems, where)}")
    qpos_idx, dof_idx, act_idx = [], [], []
    for j in robot.joints:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        qpos_idx.append(model.jnt_qposadr[jid])
        dof_idx.append(model.jnt_dofadr[jid])
        act_idx.append(joint_actuators(model, jid)[0])
    robot_geoms = model.body_rootid[model.geom_bodyid] != 0
    return SimModel(model, np.array(qpos_idx), np.array(dof_idx), np.array(act_idx), robot_geoms)


def wrist_site_positions(robot: RobotConfig, q_rad: np.ndarray) -> np.ndarray:
    """Positions of the robot's wrist sites (every site named ``*wrist_site``) along joint angles.

    Parameters
    ----------
    robot : RobotConfig
    q_rad : ndarray [shape=(T, J)], radians
        Joint angles in the robot's YAML order.

    Returns
    -------
    ndarray [shape=(T, W, 3)], metres
        World positions by forward kinematics (no dynamics).

    Raises
    ------
    ConfigError
        The model has no wrist site.
    """
    sim = load_sim_model(robot)
    m = sim.model
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) or "" for i in range(m.nsite)]
    ids = [i for i, n in enumerate(names) if n.endswith("wrist_site")]
    if not ids:
        raise ConfigError(f"{robot.path or robot.name}: the model has no site named *wrist_site; add one per wrist")
    data = mujoco.MjData(m)
    _reset_to(sim, data, None)
    q = np.asarray(q_rad, dtype=np.float64)
    out = np.zeros((q.shape[0], len(ids), 3))
    for k in range(q.shape[0]):
        data.qpos[sim.qpos_idx] = q[k]
        mujoco.mj_kinematics(m, data)
        out[k] = data.site_xpos[ids]
    return out


def _reset_to(sim: SimModel, data: mujoco.MjData, q_rad: np.ndarray | None) -> None:
    """Home keyframe (if any), then ``q_rad`` on top, at rest (zero velocity), ctrl = q."""
    key = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY)
    if key >= 0:
        mujoco.mj_resetDataKeyframe(sim.model, data, key)
    else:
        mujoco.mj_resetData(sim.model, data)
    if q_rad is not None:
        data.qpos[sim.qpos_idx] = q_rad
        data.ctrl[sim.act_idx] = q_rad
    mujoco.mj_forward(sim.model, data)


def _robot_contacts(sim: SimModel, data: mujoco.MjData) -> int:
    """Number of active contacts between two robot geoms (self-collisions; floor contacts excluded)."""
    if data.ncon == 0:
        return 0
    g1 = data.contact.geom1[: data.ncon]
    g2 = data.contact.geom2[: data.ncon]
    return int(np.count_nonzero(sim.robot_geoms[g1] & sim.robot_geoms[g2]))


@register_backend("sim")
class MujocoBackend(Backend):
    """The robot in MuJoCo, driven like a servo bus; time passes only in :meth:`advance`.

    Parameters
    ----------
    robot : RobotConfig
    start_q_rad : ndarray [shape=(J,)], radians, optional
        Initial joint angles; default the ``home`` keyframe (the rest pose).
    record : bool
        Keep ``(t, goal, achieved)`` at connect and after every :meth:`advance` (see :attr:`log`).
    count_contacts : bool
        Count physics steps in which two robot parts touch (:attr:`self_collision_s`).
    pace : bool
        Keep simulated time from running ahead of the wall clock (for watching it live).
    **options
        Ignored (so the CLI can pass hardware options such as ``port`` to any backend).
    """

    realtime = False

    def __init__(
        self,
        robot: RobotConfig,
        *,
        start_q_rad: np.ndarray | None = None,
        record: bool = True,
        count_contacts: bool = False,
        pace: bool = False,
        **options: object,
    ) -> None:
        super().__init__(robot)
        self._start = None if start_q_rad is None else np.asarray(start_q_rad, dtype=float)
        self._record = record
        self.count_contacts = count_contacts
        self.pace = pace
        #: Called as ``f(model, data)`` after every physics step (video frames, the viewer).
        self.observers: list[Callable[[mujoco.MjModel, mujoco.MjData], None]] = []
        self.self_collision_s = 0.0  #: simulated time with two robot parts touching (with ``count_contacts``)
        self._wall0 = 0.0
        self.sim: SimModel | None = None
        self.data: mujoco.MjData | None = None
        self._torque = True
        self._goal = robot.rest_q_rad.copy()
        self._t_target = 0.0
        self._log_t: list[float] = []
        self._log_goal: list[np.ndarray] = []
        self._log_q: list[np.ndarray] = []

    # --- Backend interface ----------------------------------------------------------------------
    def connect(self) -> None:
        self.sim = load_sim_model(self.robot)
        self.data = mujoco.MjData(self.sim.model)
        _reset_to(self.sim, self.data, self._start)
        self._goal = self.data.ctrl[self.sim.act_idx].copy()
        self._t_target = 0.0
        self.self_collision_s = 0.0
        self._wall0 = time.perf_counter()
        self.set_torque(True)
        self._connected()
        self._log()

    def _need(self) -> tuple[SimModel, mujoco.MjData]:
        if self.sim is None or self.data is None:
            raise BackendError("simulator not connected; call connect() first (or use the backend as `with`)")
        return self.sim, self.data

    def read_positions(self) -> np.ndarray:
        sim, data = self._need()
        q_rad: np.ndarray = data.qpos[sim.qpos_idx].copy()
        return q_rad

    def read_velocities(self) -> np.ndarray:
        """Present joint velocities ``(J,)``, rad/s."""
        sim, data = self._need()
        v_rad_s: np.ndarray = data.qvel[sim.dof_idx].copy()
        return v_rad_s

    def set_torque(self, on: bool) -> None:
        """Torque off disables every actuator: the arms then fall under gravity, as on hardware."""
        sim, _ = self._need()
        if on:
            sim.model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)
        else:
            sim.model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)
        self._torque = on

    def _send_goal(self, q_rad: np.ndarray) -> None:
        sim, data = self._need()
        self._goal = np.array(q_rad, dtype=float)
        data.ctrl[sim.act_idx] = self._goal

    def advance(self, dt_s: float) -> None:
        """Step the physics by ``dt_s`` seconds (rounded to whole timesteps, with no drift over many calls)."""
        sim, data = self._need()
        model = sim.model
        ts = model.opt.timestep
        self._t_target += float(dt_s)
        while data.time < self._t_target - 0.5 * ts:
            mujoco.mj_step(model, data)
            if self.count_contacts and _robot_contacts(sim, data):
                self.self_collision_s += ts
            for observe in self.observers:
                observe(model, data)
        if not np.all(np.isfinite(data.qpos)):
            raise BackendError(f"simulation of {self.robot.name} diverged (NaN state) at t={data.time:.3f} s")
        if self.pace:
            lag = data.time - (time.perf_counter() - self._wall0)
            if lag > 0.002:
                time.sleep(lag)
        self._log()

    def _log(self) -> None:
        if self._record and self.sim is not None and self.data is not None:
            self._log_t.append(float(self.data.time))
            self._log_goal.append(self._goal.copy())
            self._log_q.append(self.data.qpos[self.sim.qpos_idx].copy())

    def disconnect(self) -> None:
        self.sim = None
        self.data = None

    @property
    def is_connected(self) -> bool:
        return self.sim is not None

    def shutdown(self) -> None:
        """Glide to rest within every limit (:func:`~robogest.backends.rest.go_to_rest`, as the servo backends
        do), then torque off."""
        from robogest.backends.rest import go_to_rest

        try:
            if self.sim is not None and self._torque:
                go_to_rest(self)
        finally:
            if self.sim is not None:
                super().shutdown()
            else:
                self.disconnect()

    # --- extras for tests, the player and reports ------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulated time since connect, seconds."""
        return float(self._need()[1].time)

    @property
    def log(self) -> dict[str, np.ndarray]:
        """Recorded ``t_s (N,)``, ``goal_rad (N, J)``, ``q_rad (N, J)`` at connect and after each :meth:`advance`."""
        j = len(self.joint_names)
        return {
            "t_s": np.array(self._log_t),
            "goal_rad": np.array(self._log_goal).reshape(-1, j),
            "q_rad": np.array(self._log_q).reshape(-1, j),
        }


def _joint_order(trajectory: Trajectory, robot: RobotConfig) -> np.ndarray:
    """Index array mapping the trajectory's columns into the robot's joint order."""
    if list(trajectory.joint_names) == robot.joint_names:
        return np.arange(len(robot.joint_names))
    if sorted(trajectory.joint_names) != sorted(robot.joint_names):
        raise InputError(
            f"trajectory joints {list(trajectory.joint_names)} do not match robot {robot.name} joints "
            f"{robot.joint_names}; was it made for another robot ({trajectory.robot or 'unknown'})?"
        )
    return np.array([list(trajectory.joint_names).index(n) for n in robot.joint_names])


def _for_robot(trajectory: Trajectory, robot: RobotConfig, hold_until_s: float) -> Trajectory:
    """``trajectory`` in the robot's joint order, its last pose held until ``hold_until_s`` (the audio's end)."""
    order = _joint_order(trajectory, robot)
    q = trajectory.q_rad[:, order] if trajectory.n_frames else robot.rest_q_rad[None, :]
    t = trajectory.t_s if trajectory.n_frames else np.zeros(1)
    fps = trajectory.fps if trajectory.n_frames >= 2 else 50.0
    extra = int(np.ceil((hold_until_s - float(t[-1])) * fps - 1e-9))
    if extra > 0:
        t = np.concatenate([t, t[-1] + np.arange(1, extra + 1) / fps])
        q = np.vstack([q, np.repeat(q[-1:], extra, axis=0)])
    silent = np.zeros(len(t), dtype=bool)
    silent[: trajectory.n_frames] = trajectory.silent[: trajectory.n_frames]
    out = Trajectory.for_robot(robot, q, t_s=t, silent=silent, audio_path=trajectory.audio_path)
    if not np.all(np.isfinite(out.q_rad)):
        raise SafetyError("trajectory contains NaN/inf commands; refusing to simulate")
    return out


def simulate(
    trajectory: Trajectory,
    robot: RobotConfig,
    *,
    video_path: str | Path | None = None,
    audio: np.ndarray | None = None,
    audio_sr: int = 16000,
    width: int | None = None,
    height: int | None = None,
    video_fps: int = _render.VIDEO_FPS,
    realtime: bool = False,
    view: bool = False,
    progress: Callable[[float, float], None] | None = None,
    rate_hz: float = 50.0,
) -> SimReport:
    """Play ``trajectory`` on the simulated robot through the player and measure tracking; optionally render an MP4.

    The same path as on hardware: :func:`~robogest.backends.player.play` at ``rate_hz`` (control loop, online
    limiter, glide to rest, torque off) on a :class:`MujocoBackend` that starts at the trajectory's first pose,
    so trajectory time equals simulated time. With audio and a video, the last pose is held until the audio
    ends, so the video carries the whole utterance.

    Parameters
    ----------
    trajectory : Trajectory
        Joint commands ``(T, J)`` rad at times ``(T,)`` s; joint names must match ``robot`` (any order).
    robot : RobotConfig
    video_path : str or Path, optional
        Write an H.264 MP4 here (atomically), seen by the scene's three-quarter camera.
    audio : ndarray [shape=(N,) or (N, C)], optional
        Speech to mux into the video, float in [-1, 1] or int16, at ``audio_sr`` Hz.
    audio_sr : int
        Audio sample rate, Hz.
    width, height : int, optional
        Video frame size, pixels (even); default 1280x720 on a GPU, 640x360 in software (:func:`video_settings`).
    video_fps : int
        Video frame rate.
    realtime : bool
        Pace the simulation to the wall clock (implied by ``view``).
    view : bool
        Show the interactive MuJoCo viewer (needs a display).
    progress : callable(t_s, duration_s), optional
        Called every control tick while the trajectory plays.
    rate_hz : float
        Control rate of the player, Hz.

    Returns
    -------
    SimReport
        Tracking of the trajectory (not of the limiter's goals) by the simulated joints.
    """
    from robogest.backends.player import play

    t_wall0 = time.perf_counter()
    if view and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise MissingDependencyError(
            "the MuJoCo viewer needs a display (DISPLAY is not set); run without --view, or render a video instead"
        )
    audio_s = len(audio) / float(audio_sr) if video_path is not None and audio is not None and len(audio) else 0.0
    traj = _for_robot(trajectory, robot, audio_s)
    backend = MujocoBackend(robot, start_q_rad=traj.q_rad[0], count_contacts=True, pace=realtime or view)
    backend.connect()
    model, data = backend._need()[0].model, backend.data
    video = viewer = None
    out_path = None
    try:
        from robogest.backends.recorder import VideoRecorder, ViewerObserver

        if video_path is not None:
            settings = _render.video_settings(width, height)
            video = VideoRecorder(model, data, robot, video_path, settings, video_fps, audio, audio_sr)
            backend.observers.append(video)
        if view:
            backend.observers.append(viewer := ViewerObserver(model, data))
        rep = play(traj, backend, rate_hz=rate_hz, progress=progress)
        if video is not None:
            out_path = video.close()
    finally:
        _detach(backend, video, viewer, out_path)
    return tracking_report(trajectory, traj, backend.log, rep, backend.self_collision_s, video, out_path, t_wall0)


def _detach(
    backend: MujocoBackend, video: VideoRecorder | None, viewer: ViewerObserver | None, done: Path | None
) -> None:
    """After a simulated run: the video dropped unless it was finished (``done``), the viewer closed, the backend shut
    down."""
    if video is not None:
        if done is None:
            video.abort()
        video.release()
        backend.observers.remove(video)
    if viewer is not None:
        viewer.viewer.close()
    backend.shutdown()


def sine_test_trajectory(
    robot: RobotConfig, duration_s: float = 5.0, freq_hz: float = 0.5, fps: float = 50.0, amplitude: float = 0.4
) -> Trajectory:
    """A tracking test: every joint swings sinusoidally about the middle of its rest-side range.

    Each joint oscillates ``amplitude`` x (half its range, capped so peak velocity and acceleration stay
    within the joint's limits), centred between rest and the range middle, all in phase. Used by tests and
    for the tracking figures in the report.

    Returns
    -------
    Trajectory
        ``(T, J)`` commands at ``fps`` Hz, ``T = duration_s * fps + 1``.
    """
    t = np.arange(round(duration_s * fps) + 1) / fps
    lo, hi, rest = robot.q_min_rad, robot.q_max_rad, robot.rest_q_rad
    centre = 0.5 * (rest + 0.5 * (lo + hi))
    w = 2 * np.pi * freq_hz
    amp = amplitude * np.minimum(centre - lo, hi - centre)
    amp = np.minimum(amp, np.minimum(robot.v_max_rad_s / w, robot.a_max_rad_s2 / w**2))
    # ramp in/out over the first/last second so the start is at rest with zero velocity
    env = np.clip(np.minimum(t, t[-1] - t) / 1.0, 0, 1)
    env = env * env * (3 - 2 * env)
    q = rest + env[:, None] * ((centre - rest) + amp * np.sin(w * t)[:, None])
    return Trajectory(
        t_s=t,
        q_rad=q,
        joint_names=robot.joint_names,
        q_min_rad=lo,
        q_max_rad=hi,
        v_max_rad_s=robot.v_max_rad_s,
        a_max_rad_s2=robot.a_max_rad_s2,
        rest_q_rad=rest,
        silent=np.zeros(len(t), dtype=bool),
        robot=robot.name,
    )
