"""Export a command trajectory for other tools: a ROS 2 bag (``.mcap`` file or bag folder) or ``.csv``.

Times are on the speech audio's clock: 0 s is the first audio sample, so a bag plays in step with the
speech. The bag holds two topics (positions in radians, joint order as in the robot YAML):

``/robogest/joint_trajectory`` (``trajectory_msgs/msg/JointTrajectory``)
    One message with the whole trajectory at bag time 0; ``header.stamp`` is 0 (the audio's start; a
    ros2_control joint trajectory controller reads a zero stamp as "start on receipt"), point ``k`` has
    ``time_from_start = t_s[k]``. Remap it onto a controller's ``~/joint_trajectory`` topic to play it.
``/robogest/joint_commands`` (``sensor_msgs/msg/JointState``)
    One message per command frame, ``header.stamp = t_s[k]`` (bag time the same), for plotting
    (Foxglove, PlotJuggler) or a position controller.

The bag is written with the pure-Python ``rosbags`` library (``pip install 'robogest[ros]'``); no ROS
installation is needed.
"""

from __future__ import annotations

import csv
import io
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from robogest.errors import InputError, MissingDependencyError
from robogest.fileio import atomic_path, check_output_parent, publish, write_error
from robogest.trajectory.types import Trajectory

TRAJECTORY_TOPIC = "/robogest/joint_trajectory"
COMMANDS_TOPIC = "/robogest/joint_commands"
#: What ``--export`` accepts, by file name.
EXPORT_FORMATS = "FILE.mcap (ROS 2 bag, one file), FILE.csv, or a name without suffix (ROS 2 bag folder)"


def export_format(path: str | Path) -> str:
    """``"csv"``, ``"mcap"`` or ``"bag"`` (folder) for ``path``; raises :class:`InputError` for anything else."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".csv", ".mcap"):
        return suffix[1:]
    if suffix:
        raise InputError(f"--export {path}: unknown format {path.suffix!r}; write {EXPORT_FORMATS}")
    if path.exists():
        raise InputError(f"--export {path}: already exists; a bag folder is never overwritten, choose a new name")
    return "bag"


def check_export(path: str | Path) -> None:
    """Everything :func:`export_trajectory` could refuse (name, existing folder, missing rosbags), checked
    before any motion starts so a wrong ``--export`` fails at once rather than after playback."""
    fmt = export_format(path)
    if fmt == "bag" and os.path.islink(path):  # a dangling link: the bag would be renamed over it
        raise InputError(f"--export {path}: is a symlink; a bag folder is made new, give a name that is not taken")
    check_output_parent(path, "--export")
    if fmt in ("mcap", "bag"):
        _rosbags()


def export_trajectory(traj: Trajectory, path: str | Path) -> Path:
    """Write ``traj`` to ``path``; the format follows the name (see :data:`EXPORT_FORMATS`).

    A ``.mcap`` or ``.csv`` file is replaced atomically; a bag folder must not exist yet (it is never
    overwritten). Returns the path written.
    """
    path = Path(path)
    writer = {"csv": write_csv, "mcap": write_mcap, "bag": write_bag_folder}[export_format(path)]
    writer(traj, path)
    return path


def write_csv(traj: Trajectory, path: Path) -> None:
    """One row per command frame: ``t_s``, ``silent`` (0/1), then each joint's position as ``<joint>_rad``."""
    buf = io.StringIO()  # csv quotes a joint name holding a comma or a quote
    csv.writer(buf, lineterminator="").writerow(["t_s", "silent", *(f"{name}_rad" for name in traj.joint_names)])
    header = buf.getvalue()
    table = np.column_stack([traj.t_s, traj.silent.astype(float), traj.q_rad])
    fmt = ["%.6f", "%d", *(["%.9f"] * traj.q_rad.shape[1])]
    with atomic_path(path, ".csv") as tmp:
        np.savetxt(tmp, table, fmt=fmt, delimiter=",", header=header, comments="")


def _rosbags() -> tuple[Any, Any, Any]:
    """rosbags' ``StoragePlugin``, ``Writer`` and the ROS 2 Humble type store (untyped library classes)."""
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        from robogest.extras import install_command

        raise MissingDependencyError(
            f"writing a ROS 2 bag needs the rosbags library: {install_command('ros')} (or export to .csv)"
        ) from None
    return StoragePlugin, Writer, get_typestore(Stores.ROS2_HUMBLE)


def _stamp_ns(t_s: np.ndarray) -> np.ndarray:
    """Seconds -> integer nanoseconds, rounded (never truncated: 0.02 s must be 20 000 000 ns)."""
    return np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)


def _write_bag(traj: Trajectory, folder: Path) -> None:
    """A rosbag2 folder (``metadata.yaml`` + ``<folder name>.mcap``) at ``folder``, which must not exist."""
    StoragePlugin, Writer, store = _rosbags()
    T = store.types
    Time, Duration = T["builtin_interfaces/msg/Time"], T["builtin_interfaces/msg/Duration"]
    Header = T["std_msgs/msg/Header"]
    Trajectory_, Point = T["trajectory_msgs/msg/JointTrajectory"], T["trajectory_msgs/msg/JointTrajectoryPoint"]
    JointState = T["sensor_msgs/msg/JointState"]
    empty = np.zeros(0, dtype=np.float64)
    names = list(traj.joint_names)
    ns = _stamp_ns(traj.t_s)
    q = np.ascontiguousarray(traj.q_rad, dtype=np.float64)

    def header(t_ns: int) -> object:
        return Header(stamp=Time(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000)), frame_id="")

    points = [
        Point(
            positions=q[k].copy(), velocities=empty, accelerations=empty, effort=empty,
            time_from_start=Duration(sec=int(ns[k] // 1_000_000_000), nanosec=int(ns[k] % 1_000_000_000)),
        )
        for k in range(traj.n_frames)
    ]  # fmt: skip
    whole = Trajectory_(header=header(0), joint_names=names, points=points)

    writer = Writer(folder, version=8, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    try:
        conn_traj = writer.add_connection(TRAJECTORY_TOPIC, Trajectory_.__msgtype__, typestore=store)
        conn_cmd = writer.add_connection(COMMANDS_TOPIC, JointState.__msgtype__, typestore=store)
        writer.write(conn_traj, 0, store.serialize_cdr(whole, Trajectory_.__msgtype__))
        for k in range(traj.n_frames):
            msg = JointState(header=header(int(ns[k])), name=names, position=q[k].copy(), velocity=empty, effort=empty)
            writer.write(conn_cmd, int(ns[k]), store.serialize_cdr(msg, JointState.__msgtype__))
    finally:
        writer.close()


@contextmanager
def _staged_bag(traj: Trajectory, target: Path, stem: str) -> Iterator[Path]:
    """The bag folder ``<hidden temporary folder beside target>/<stem>``, written; the temporary folder (and what
    the caller did not move out of it) goes when the block ends. A disk that fills mid-write is one line."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".{target.name}.", dir=target.parent) as tmp:
        staged = Path(tmp) / stem
        try:
            _write_bag(traj, staged)
        except OSError as e:
            raise write_error(target, e) from None
        yield staged


def write_bag_folder(traj: Trajectory, folder: Path) -> None:
    """A rosbag2 folder for ``ros2 bag play FOLDER``; refuses to touch an existing path."""
    export_format(folder)  # refuses an existing path
    with _staged_bag(traj, folder, folder.name) as staged:
        staged.rename(folder)  # the finished bag appears at once


def write_mcap(traj: Trajectory, path: Path) -> None:
    """The bag as one ``.mcap`` file (self-describing: ``ros2 bag play FILE.mcap`` needs no metadata.yaml)."""
    with _staged_bag(traj, path, path.stem) as staged:
        publish(staged / f"{path.stem}.mcap", path)
