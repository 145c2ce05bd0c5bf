"""The ``--plot`` figure: speech, wrists and joint commands, in rows of about ten seconds.

A minute of speech on one time axis squeezes 200 words into the width of a page. Instead the time axis is cut into
rows of :data:`ROW_S` seconds stacked in one PNG (every row the same scale); speech longer than
``MAX_ROWS * ROW_S`` gets longer rows (20 s, 30 s, a minute, ...) so the image stays at most :data:`MAX_ROWS` rows
tall. Word labels are thinned so that none overlap (:mod:`robogest.viz.labels`); joints are coloured by limb with a
legend per limb (:mod:`robogest.viz.joints`). Drawn on a ``Figure`` with the Agg canvas: no display, no pyplot state.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.fileio import atomic_path
from robogest.motion.human_motion import HumanMotion
from robogest.speech.types import Speech
from robogest.trajectory import Trajectory
from robogest.viz.joints import JointStyle, column_legend, joint_groups, joint_styles
from robogest.viz.labels import Label, place_labels

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from robogest.robot.config import RobotConfig

#: Seconds of time axis per row.
ROW_S = 10.0
#: Most rows in one figure; longer speech gets longer rows (from :data:`_LONG_ROWS_S`).
MAX_ROWS = 12
_LONG_ROWS_S = (20.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0, 7200.0)
#: Panel heights, inches.
_PANEL_IN = {"audio": 1.0, "height": 0.85, "speed": 0.85, "joints": 1.3}
_ROW_GAP_IN = 0.3
_WIDTH_IN, DPI = 11.0, 110
_WRISTS = (("l", "left wrist", "tab:blue"), ("r", "right wrist", "tab:orange"))
_BEAT, _PSEUDO_BEAT, _SILENT = "tab:red", "tab:pink", "0.85"


def row_spans(duration_s: float) -> list[tuple[float, float]]:
    """``(start_s, end_s)`` of each row: one row for a clip up to :data:`ROW_S`, else rows of equal length."""
    if duration_s <= ROW_S:
        return [(0.0, max(duration_s, 1e-3))]
    row_s = next((r for r in (ROW_S, *_LONG_ROWS_S) if duration_s <= r * MAX_ROWS), _LONG_ROWS_S[-1])
    return [(k * row_s, (k + 1) * row_s) for k in range(math.ceil(duration_s / row_s))]


def plot_motion(
    path: str | Path,
    motion: HumanMotion,
    speech: Speech | None = None,
    trajectory: Trajectory | None = None,
    robot: RobotConfig | None = None,
) -> None:
    """Write :func:`motion_figure` as a PNG (atomically: a failure leaves no half-written file)."""
    _save(motion_figure(motion, speech, trajectory, robot), Path(path))


def motion_figure(
    motion: HumanMotion,
    speech: Speech | None = None,
    trajectory: Trajectory | None = None,
    robot: RobotConfig | None = None,
) -> Figure:
    """Wrist height and speed over time, beats as vertical lines, silent spans shaded; words and joint commands.

    Parameters
    ----------
    motion : the generated human motion.
    speech : optional; adds the waveform with word labels, beats and silent spans.
    trajectory : optional; adds the robot's joint commands (degrees), coloured by limb.
    robot : optional; its import record (``import: arms:, head:``) says which joints are which limb, where the
        names do not.
    """
    ends = [motion.duration_s, speech.duration_s if speech else 0.0]
    ends.append(float(trajectory.t_s[-1]) if trajectory is not None and trajectory.n_frames else 0.0)
    spans = row_spans(max(ends))
    panels = ["audio"] * (speech is not None) + ["height", "speed"] + ["joints"] * (trajectory is not None)
    fig, canvas, rows = _layout(spans, panels)
    pos = motion.positions()  # (T, J, 3) metres
    wrists = []
    for side, _label, colour in _WRISTS:
        w = pos[:, motion.skeleton.index(f"{side}_wrist")]
        step = np.gradient(w, axis=0) if len(w) > 1 else np.zeros_like(w)  # one frame: no speed
        speed = np.linalg.norm(step, axis=1) * motion.fps * 100.0  # cm/s
        wrists.append((w[:, 1], speed, colour))
    styles = joint_styles(trajectory.joint_names, robot) if trajectory is not None else []
    peak = float(np.abs(speech.audio).max() or 1.0) if speech is not None else 1.0
    for (t0, t1), axes in zip(spans, rows, strict=True):
        if speech is not None:
            _draw_audio(axes["audio"], speech, t0, t1, peak)
        _draw_wrists(axes["height"], axes["speed"], motion, wrists, t0, t1)
        if trajectory is not None:
            _draw_joints(axes["joints"], trajectory, styles, t0, t1)
        if speech is not None:
            for a in axes.values():
                _draw_marks(a, speech, t0, t1)
    _legend(fig, trajectory, styles, robot, speech is not None)
    n_words = len(speech.words) if speech is not None else 0
    title = fig.suptitle(_title(max(ends), spans, n_words, n_words), fontsize=10)
    if speech is not None and speech.words:
        fig.draw_without_rendering()  # runs the layout: labels are measured in pixels
        fig.set_layout_engine("none")  # and keeps it: once is slow enough with 30 axes
        renderer = canvas.get_renderer()
        shown = sum(
            len(place_labels(axes["audio"], _labels(speech, t0, t1), renderer))
            for (t0, t1), axes in zip(spans, rows, strict=True)
        )
        title.set_text(_title(max(ends), spans, n_words, shown))
    return fig


def _layout(
    spans: list[tuple[float, float]], panels: list[str]
) -> tuple[Figure, FigureCanvasAgg, list[dict[str, Axes]]]:
    """The figure, its Agg canvas and each row's axes by panel name; rows share the y scale of each panel, a row
    its x axis."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ratios = []
    for k in range(len(spans)):
        ratios += [_ROW_GAP_IN] * (k > 0) + [_PANEL_IN[p] for p in panels]
    fig = Figure(figsize=(_WIDTH_IN, sum(ratios) + 1.6), dpi=DPI, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    grid = fig.add_gridspec(len(ratios), 1, height_ratios=ratios)
    first: dict[str, Axes] = {}
    rows: list[dict[str, Axes]] = []
    slot = 0
    for k, (t0, t1) in enumerate(spans):
        slot += k > 0
        row: dict[str, Axes] = {}
        for i, p in enumerate(panels):
            top = next(iter(row.values()), None)
            a = fig.add_subplot(grid[slot + i], sharex=top, sharey=first.get(p))
            first.setdefault(p, a)
            row[p] = a
            a.tick_params(labelsize=7, labelbottom=i == len(panels) - 1)
            a.set_ylabel(_YLABEL[p], fontsize=8)
            a.margins(x=0)
        slot += len(panels)
        row[panels[0]].set_xlim(t0, t1)
        rows.append(row)
    rows[-1][panels[-1]].set_xlabel("time (s)", fontsize=8)
    return fig, canvas, rows


_YLABEL = {"audio": "words", "height": "height (m)", "speed": "speed (cm/s)", "joints": "joints (deg)"}


def _window(t: np.ndarray, t0: float, t1: float) -> slice:
    """Indices of ``t`` (increasing) covering ``[t0, t1]``, one sample beyond each end so lines reach the edges."""
    i0 = max(0, int(np.searchsorted(t, t0)) - 1)
    return slice(i0, int(np.searchsorted(t, t1, side="right")) + 1)


def _draw_audio(a: Axes, speech: Speech, t0: float, t1: float, peak: float) -> None:
    """The waveform as a min/max envelope in the lower part of the panel; the top is kept for word labels."""
    i0, i1 = round(t0 * speech.sr), min(len(speech.audio), round(t1 * speech.sr))
    if i1 - i0 >= 2:
        n_bins = min(2000, (i1 - i0) // 2)
        chunks = np.array_split(speech.audio[i0:i1], n_bins)
        mid = i0 + np.cumsum([0] + [len(c) for c in chunks[:-1]])
        lo, hi = [c.min() for c in chunks], [c.max() for c in chunks]
        a.fill_between(mid / speech.sr, lo, hi, color="0.4", lw=0)
    a.set_ylim(-peak, 1.9 * peak)
    a.set_yticks([])


def _draw_wrists(a_h: Axes, a_v: Axes, motion: HumanMotion, wrists: list, t0: float, t1: float) -> None:
    """Each wrist's height (m) and speed (cm/s): ``wrists`` holds ``(height (T,), speed (T,), colour)``."""
    t = motion.t_s
    w = _window(t, t0, t1)
    for height, speed, colour in wrists:
        a_h.plot(t[w], height[w], color=colour, lw=0.9)
        a_v.plot(t[w], speed[w], color=colour, lw=0.9)


def _draw_joints(a: Axes, traj: Trajectory, styles: list[JointStyle], t0: float, t1: float) -> None:
    w = _window(traj.t_s, t0, t1)
    q_deg = np.degrees(traj.q_rad[w])
    for j, s in enumerate(styles):
        a.plot(traj.t_s[w], q_deg[:, j], color=s.colour, ls=s.line_style, lw=0.8)


def _draw_marks(a: Axes, speech: Speech, t0: float, t1: float) -> None:
    """Silent spans shaded, beats as vertical lines (pseudo beats paler)."""
    for b0, b1 in speech.silent_spans:
        if b1 > t0 and b0 < t1:
            a.axvspan(max(b0, t0), min(b1, t1), color=_SILENT, zorder=0, lw=0)
    beats = np.asarray(speech.beats_s)
    inside = (beats >= t0) & (beats <= t1)
    pseudo = np.asarray(speech.beat_is_pseudo, dtype=bool)
    for sel, colour in ((inside & ~pseudo, _BEAT), (inside & pseudo, _PSEUDO_BEAT)):
        if sel.any():
            a.vlines(beats[sel], 0, 1, transform=a.get_xaxis_transform(), colors=colour, lw=0.6, alpha=0.6)


def _labels(speech: Speech, t0: float, t1: float) -> list[Label]:
    """The row's words (by start), stressed ones (holding a beat that is not a pseudo beat) and longer ones first."""
    real = np.asarray(speech.beats_s)[~np.asarray(speech.beat_is_pseudo, dtype=bool)]
    out = []
    for w in speech.words:
        if t0 <= w.start_s < t1:
            stressed = bool(((real >= w.start_s) & (real <= w.end_s)).any())
            priority = 10.0 * stressed + 2.0 * (not w.is_filler) + (w.end_s - w.start_s)
            out.append(Label(w.text, w.start_s, w.end_s, priority))
    return out


def _legend(
    fig: Figure, traj: Trajectory | None, styles: list[JointStyle], robot: RobotConfig | None, marks: bool
) -> None:
    """One key below the rows: wrists, beat marks, and a column of joints per limb."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    columns: dict[str, list[tuple[Artist, str]]] = {
        "wrists": [(Line2D([], [], color=c), label) for _, label, c in _WRISTS]
    }
    if marks:
        columns["marks"] = [
            (Line2D([], [], color=_BEAT), "beat"),
            (Line2D([], [], color=_PSEUDO_BEAT), "pseudo beat"),
            (Patch(color=_SILENT), "silent span"),
        ]
    if traj is not None:
        for group, idx in joint_groups(traj.joint_names, robot).items():
            columns[group] = [
                (Line2D([], [], color=styles[j].colour, ls=styles[j].line_style), traj.joint_names[j]) for j in idx
            ]
    column_legend(fig, columns, fontsize=7, frameon=False)


def _title(duration_s: float, spans: list, n_words: int, shown: int) -> str:
    text = f"{duration_s:.1f} s"
    if n_words:
        text += f", {n_words} words ({shown} labelled: stressed and longer words first)"
    if len(spans) > 1:
        text += f"; rows of {spans[0][1] - spans[0][0]:g} s"
    return text


def _save(fig: Figure, path: Path) -> None:
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi="figure", format="png")
