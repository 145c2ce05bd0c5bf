"""Word labels that never overlap: each is measured with the renderer and kept only where it fits.

Speech has about three words a second; at a readable font size a row of ten seconds holds most of them, a row of
a minute few. Labels are placed in priority order (stressed, then longer words first) on a few lanes at the top of
an axes; one that would touch a placed label, or stick out of the axes, tries the next lane, then is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.backend_bases import RendererBase
    from matplotlib.text import Text
    from matplotlib.transforms import Bbox

#: Gap kept between two labels, and between a label and the axes' edge, pixels.
PAD_PX = 2.0


@dataclass(frozen=True)
class Label:
    """A label to place: ``text`` from ``start_s`` to ``end_s`` (data x), higher ``priority`` placed first."""

    text: str
    start_s: float
    end_s: float
    priority: float


def place_labels(
    ax: Axes, labels: list[Label], renderer: RendererBase, lanes: int = 2, fontsize: float = 7.0
) -> list[Text]:
    """Add the labels that fit to ``ax`` and return them; the others are left out.

    Call it after the figure's layout is final (after one ``draw``): positions are measured in pixels. Each label
    is left-aligned at its word's start, or right-aligned at its end when that is what keeps it inside the axes.
    The labels are kept out of the layout (``in_layout=False``), so adding them moves nothing.
    """
    box = ax.get_window_extent(renderer)
    placed: list[tuple[int, float, float]] = []  # (lane, x0, x1) in pixels
    texts: list[Text] = []
    line_px = None
    for label in sorted(labels, key=lambda lb: -lb.priority):
        t = ax.text(0, 0, label.text, fontsize=fontsize, va="top", clip_on=True, transform=ax.get_xaxis_transform())
        t.set_in_layout(False)
        if line_px is None:
            line_px = t.get_window_extent(renderer).height + PAD_PX
        if _fit(ax, t, label, renderer, box, placed, lanes, line_px):
            texts.append(t)
        else:
            t.remove()
    return texts


def _fit(
    ax: Axes,
    t: Text,
    label: Label,
    renderer: RendererBase,
    box: Bbox,
    placed: list[tuple[int, float, float]],
    lanes: int,
    line_px: float,
) -> bool:
    """Move ``t`` to the first lane and alignment where it overlaps nothing placed; False when there is none."""
    for lane in range(lanes):
        y_frac = 1.0 - (PAD_PX + lane * line_px) / box.height  # x in data (s), y in axes fraction
        aligns: tuple[tuple[float, Literal["left", "right"]], ...] = ((label.start_s, "left"), (label.end_s, "right"))
        for x_s, ha in aligns:
            t.set_horizontalalignment(ha)
            t.set_position((x_s, y_frac))
            ext = t.get_window_extent(renderer)
            if ext.x0 < box.x0 + PAD_PX or ext.x1 > box.x1 - PAD_PX:
                continue
            if all(ln != lane or ext.x1 + PAD_PX <= a or ext.x0 >= b + PAD_PX for ln, a, b in placed):
                placed.append((lane, ext.x0, ext.x1))
                return True
    return False
