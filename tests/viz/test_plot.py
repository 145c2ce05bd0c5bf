"""The --plot figure is readable: no text over other text, a legend of joints by limb, rows covering the speech."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from robogest.motion.human_motion import HumanMotion
from robogest.speech.types import Speech, SpeechFeatures, Word
from robogest.trajectory import Trajectory
from robogest.viz import plot as viz_plot

JOINTS = [  # humanoid_sts3215's
    "torso_yaw", "head_pan", "head_tilt",
    "l_shoulder_pitch", "l_shoulder_roll", "l_upper_arm_yaw", "l_elbow",
    "r_shoulder_pitch", "r_shoulder_roll", "r_upper_arm_yaw", "r_elbow",
]  # fmt: skip
VOCAB = ["so", "I", "think", "that", "the", "robot", "should", "gesture", "naturally", "while", "it", "speaks",
         "about", "extraordinary", "things", "um", "and", "conversations", "we", "a"]  # fmt: skip


def make_speech(duration_s: float, n_words: int, sr: int = 8000, fps: float = 20.0) -> Speech:
    """Speech with ``n_words`` words spread over ``duration_s`` (pauses every ~20 words), a beat on most words."""
    rng = np.random.default_rng(3)
    starts = np.sort(rng.uniform(0.05, duration_s - 0.4, n_words))
    words = []
    for k, s in enumerate(starts):
        end = min(s + rng.uniform(0.12, 0.5), starts[k + 1] if k + 1 < n_words else duration_s)
        words.append(Word(VOCAB[k % len(VOCAB)], float(s), float(max(end, s + 0.02)), 1))
    beats = np.array([w.start_s + 0.03 for k, w in enumerate(words) if k % 3])
    audio = (0.3 * np.sin(np.arange(round(duration_s * sr)) * 0.2) * rng.random(round(duration_s * sr))).astype(
        np.float32
    )
    n = int(duration_s * fps)
    feats = SpeechFeatures(
        fps=fps, mel_db=np.zeros((n, 64)), mfcc=np.zeros((n, 37)), rms=np.ones(n), pitch_hz=np.zeros(n),
        word_features=np.zeros((n, 5)), filler=np.zeros(n, bool), silence=np.zeros(n, bool),
    )  # fmt: skip
    return Speech(
        audio=audio, sr=sr, words=tuple(words), beats_s=beats, beat_is_pseudo=np.arange(len(beats)) % 7 == 0,
        silent_spans=((duration_s / 3, duration_s / 3 + 0.6),), noise_level=1e-3, features=feats, source="test",
    )  # fmt: skip


def make_trajectory(duration_s: float, fps: float = 50.0) -> Trajectory:
    t = np.arange(round(duration_s * fps) + 1) / fps
    j = len(JOINTS)
    q = 0.5 * np.sin(t[:, None] * (1.0 + 0.2 * np.arange(j)))
    ones = np.ones(j)
    return Trajectory(t, q, list(JOINTS), -2 * ones, 2 * ones, 3 * ones, 15 * ones, 0 * ones, np.zeros(len(t), bool))


def render(monkeypatch, tmp_path, duration_s: float, n_words: int):
    """Plot through ``plot_motion`` (as the CLI does), keep the figure it saves, and draw it."""
    saved = []
    real_save = viz_plot._save
    monkeypatch.setattr(viz_plot, "_save", lambda fig, path: (saved.append(fig), real_save(fig, path)))
    motion = HumanMotion.rest(round(duration_s * 20), 20.0)
    path = tmp_path / "p.png"
    viz_plot.plot_motion(path, motion, make_speech(duration_s, n_words), make_trajectory(duration_s))
    assert path.stat().st_size > 10_000
    fig = saved[0]
    if not hasattr(fig.canvas, "get_renderer"):  # pyplot.close() took the Agg canvas away
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig)
    fig.canvas.draw()
    return fig, fig.canvas.get_renderer()


def texts_drawn(fig, renderer) -> list[tuple[str, object, str]]:
    """``(kind, window extent, text)`` of every text the figure shows: titles, axis and tick labels, legend, words."""
    out = []

    def add(kind, t):
        if t.get_visible() and t.get_text().strip():
            out.append((kind, t.get_window_extent(renderer), t.get_text()))

    if fig._suptitle is not None:
        add("title", fig._suptitle)
    for leg in fig.legends:
        for t in leg.get_texts():
            add("legend", t)
    for ax in fig.axes:
        for t in (ax.title, ax.xaxis.label, ax.yaxis.label):
            add("axis label", t)
        for axis, lim in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            for tick in axis.get_major_ticks():
                if min(lim) <= tick.get_loc() <= max(lim):
                    add("tick", tick.label1)
        for t in ax.texts:
            add("word", t)
        if ax.get_legend() is not None:
            for t in ax.get_legend().get_texts():
                add("legend", t)
    return out


def overlaps(texts) -> list[str]:
    """Pairs of texts whose boxes overlap, where at least one is a word label, or both are titles/legend."""
    bad = []
    for (k1, b1, s1), (k2, b2, s2) in itertools.combinations(texts, 2):
        if "word" not in (k1, k2) and not {k1, k2} <= {"title", "legend", "axis label"}:
            continue  # tick labels against each other are matplotlib's business
        if b1.x0 < b2.x1 and b2.x0 < b1.x1 and b1.y0 < b2.y1 and b2.y0 < b1.y1:
            bad.append(f"{k1} {s1!r} over {k2} {s2!r}")
    return bad


def rows_cover(fig, duration_s: float) -> bool:
    spans = sorted({tuple(round(v, 6) for v in ax.get_xlim()) for ax in fig.axes})
    return spans[0][0] <= 0.0 and spans[-1][1] >= duration_s and all(a[1] >= b[0] for a, b in itertools.pairwise(spans))


def legend_labels(fig) -> set[str]:
    return {t.get_text() for leg in [*fig.legends, *(a.get_legend() for a in fig.axes)] if leg for t in leg.get_texts()}


@pytest.mark.slow
def test_64_s_of_speech_is_readable(monkeypatch, tmp_path):
    fig, renderer = render(monkeypatch, tmp_path, 64.0, 199)
    texts = texts_drawn(fig, renderer)
    assert overlaps(texts) == []
    words = [t for t in texts if t[0] == "word"]
    assert len(words) >= 0.5 * 199  # thinned, not dropped wholesale
    title = next(b for k, b, _ in texts if k == "title")
    assert all(b.y1 < title.y0 for k, b, _ in texts if k != "title")  # the title above everything
    assert rows_cover(fig, 64.0)
    assert len({ax.get_xlim() for ax in fig.axes}) == 7  # rows of 10 s
    assert {"left arm", "right arm", "head", "waist"} <= legend_labels(fig)
    assert set(JOINTS) <= legend_labels(fig)


def test_short_clip_has_a_legend_and_all_words(monkeypatch, tmp_path):
    fig, renderer = render(monkeypatch, tmp_path, 2.5, 6)
    texts = texts_drawn(fig, renderer)
    assert overlaps(texts) == []
    assert len([t for t in texts if t[0] == "word"]) == 6
    assert {ax.get_xlim() for ax in fig.axes} == {(0.0, 2.5)}  # one row, the clip's length
    assert {"left arm", "right arm", "head", "waist"} <= legend_labels(fig)


@pytest.mark.slow
def test_speak_plot_through_the_cli(tmp_path, capsys):
    from robogest.cli.main import main

    png = tmp_path / "s.png"
    assert main(["speak", "Hello there, nice to meet you.", "--plot", str(png), "--fps", "25"]) == 0
    assert f"plot: {png}" in capsys.readouterr().out and png.stat().st_size > 10_000


def test_eval_trajectory_plot_groups_joints_below_the_axes(monkeypatch, tmp_path):
    from robogest.eval import plots as eval_plots

    saved = []
    real_save = eval_plots._save
    monkeypatch.setattr(eval_plots, "_save", lambda fig, path: (saved.append(fig), real_save(fig, path))[1])
    assert eval_plots.plot_trajectory(make_trajectory(20.0), tmp_path / "t.png", "clip1").stat().st_size > 10_000
    fig = saved[0]
    fig.canvas.draw()
    texts = texts_drawn(fig, fig.canvas.get_renderer())
    assert overlaps(texts) == []
    assert {"left arm", "right arm", "head", "waist", *JOINTS} <= legend_labels(fig)
    (ax,) = fig.axes
    assert all(b.y1 < ax.get_window_extent().y0 for k, b, _ in texts if k == "legend")  # not over the lines


@pytest.mark.parametrize(
    ("name", "group"),
    [
        ("l_shoulder_pitch", "left arm"), ("right_elbow_joint", "right arm"), ("left_hip_pitch_joint", "legs"),
        ("knee", "legs"), ("waist_yaw_joint", "waist"), ("torso_yaw", "waist"), ("head_tilt", "head"),
        ("neck_pitch", "head"), ("shoulder_pan", "arm"), ("gripper", "arm"), ("base_yaw", "waist"),
        ("l_foo", "other"), ("joint7", "other"),
    ],
)  # fmt: skip
def test_joint_group_from_name(name, group):
    from robogest.viz.joints import joint_group

    assert joint_group(name) == group


def test_imported_robot_record_decides_the_groups():
    from types import SimpleNamespace

    from robogest.viz.joints import joint_groups, joint_styles

    record = SimpleNamespace(arms={"left": ["j1", "j2"], "right": ["j3"]}, head=["j4"])
    names = ["j1", "j2", "j3", "j4", "j5"]
    groups = joint_groups(names, SimpleNamespace(import_record=record))
    assert groups == {"left arm": [0, 1], "right arm": [2], "head": [3], "other": [4]}
    legs = [f"left_{p}_joint" for p in ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch", "ankle_roll")]
    styles = joint_styles(legs)
    assert len({(s.colour, s.line_style) for s in styles}) == 6  # six leg joints, six looks
