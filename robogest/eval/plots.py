"""Diagnostic plots. Uses ``matplotlib.figure.Figure`` directly (Agg canvas, no pyplot global state), so
it works headless and in threads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robogest.fileio import atomic_path


def _save(fig, path: str | Path) -> Path:
    """Write ``fig`` as PNG atomically (a full disk leaves no half-written plot)."""
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    return Path(path)


def _figure(w: float = 7.0, h: float = 4.0):
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


def plot_trajectory(traj, path: str | Path, title: str = "") -> Path:
    """Joint commands over time with position limits (dashed) and silent periods shaded."""
    fig = _figure(8.0, 5.0)
    ax = fig.add_subplot()
    t = traj.t_s
    for j, name in enumerate(traj.joint_names):
        (line,) = ax.plot(t, traj.q_rad[:, j], label=name)
        ax.axhline(traj.q_min_rad[j], color=line.get_color(), ls=":", lw=0.7)
        ax.axhline(traj.q_max_rad[j], color=line.get_color(), ls=":", lw=0.7)
    if traj.n_frames:
        ax.fill_between(
            t,
            0,
            1,
            where=traj.silent.astype(bool),
            color="grey",
            alpha=0.2,
            transform=ax.get_xaxis_transform(),
            label="silent",
        )
    ax.set(xlabel="time (s)", ylabel="angle (rad)", title=title)
    ax.legend(fontsize="small", ncol=2)
    return _save(fig, path)
