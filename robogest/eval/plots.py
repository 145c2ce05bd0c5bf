"""Diagnostic plots. Uses ``matplotlib.figure.Figure`` directly (Agg canvas, no pyplot global state), so
it works headless and in threads."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.fileio import atomic_path

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.figure import Figure

    from robogest.trajectory import Trajectory


def _save(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG atomically (a full disk leaves no half-written plot)."""
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    return Path(path)


def _figure(w: float = 7.0, h: float = 4.0) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


def plot_wrist_histogram(wrist_speed: dict, path: str | Path, title: str = "") -> Path:
    """Pred vs gt wrist-speed histograms (the dict from ``wrist_speed_comparison``)."""
    fig = _figure()
    ax = fig.add_subplot()
    edges = np.asarray(wrist_speed["edges_cm_s"])
    centers = 0.5 * (edges[:-1] + edges[1:])
    ax.plot(centers, wrist_speed["gt_hist"], label="ground truth")
    ax.plot(centers, wrist_speed["pred_hist"], label="generated")
    ax.set(
        xlabel="wrist speed (cm/s)",
        ylabel="relative frequency",
        title=f"{title} Hellinger {wrist_speed['hellinger']:.3f}".strip(),
    )
    ax.legend()
    return _save(fig, path)


def plot_pmb_curves(curves: dict[str, dict], path: str | Path, title: str = "") -> Path:
    """PMB vs δ for several motions (``label -> pmb_curve dict``)."""
    fig = _figure()
    ax = fig.add_subplot()
    for label, c in curves.items():
        ax.plot(c["delta_s"], c["pmb"], marker=".", label=label)
    ax.set(xlabel="δ (s)", ylabel="PMB (%)", ylim=(0, 100), title=title)
    ax.legend()
    return _save(fig, path)


def plot_trajectory(traj: Trajectory, path: str | Path, title: str = "") -> Path:
    """Joint commands over time with position limits (dotted) and silent periods shaded; joints coloured by limb
    with a legend column per limb below the axes (the same key as ``--plot``), so that no legend covers the lines."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from robogest.viz.joints import column_legend, joint_groups, joint_styles

    fig = _figure(8.0, 5.0)
    fig.set_layout_engine("constrained")
    ax = fig.add_subplot()
    t = traj.t_s
    styles = joint_styles(traj.joint_names)
    for j, s in enumerate(styles):
        ax.plot(t, traj.q_rad[:, j], color=s.colour, ls=s.line_style)
        ax.axhline(traj.q_min_rad[j], color=s.colour, ls=":", lw=0.7)
        ax.axhline(traj.q_max_rad[j], color=s.colour, ls=":", lw=0.7)
    if traj.n_frames:
        ax.fill_between(
            t, 0, 1, where=traj.silent.astype(bool), color="grey", alpha=0.2, transform=ax.get_xaxis_transform()
        )
    ax.set(xlabel="time (s)", ylabel="angle (rad)", title=title)
    columns: dict[str, list[tuple[Artist, str]]] = {"marks": [(Line2D([], [], color="0.3", ls=":", lw=0.7), "limits")]}
    columns["marks"].append((Patch(color="grey", alpha=0.2), "silent"))
    for group, idx in joint_groups(traj.joint_names).items():
        columns[group] = [
            (Line2D([], [], color=styles[j].colour, ls=styles[j].line_style), traj.joint_names[j]) for j in idx
        ]
    column_legend(fig, columns, fontsize="small", frameon=False)
    return _save(fig, path)
