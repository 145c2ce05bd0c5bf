"""Speech2AffectiveGestures (Bhattacharya et al., ACM MM 2021, §3-4): MFCC + text + speaker style + seed poses in,
upper-body edge directions out, trained as a GAN whose discriminator sees the affective encoder's features.

Importing this module needs PyTorch (``pip install 'robogest[learn]'``); without it the import raises
:class:`~robogest.errors.MissingDependencyError`, so register the generator through a lazy factory.

Data path (all at the feature rate, 20 fps):

* **MFCC** (37 per frame, §3.1.1): computed from the take's stored 64-band log-mel spectrum by the same DCT-II the
  speech front-end uses (:func:`mfcc_from_mel`), so training needs no new cached arrays and equals
  ``Speech.features.mfcc`` at inference exactly (DCT and the frame interpolation are both linear).
* **Text** (§3.1.2): the paper's FastText 300-d vectors cannot be downloaded here; the take's per-frame vectors from
  the registered text encoder are used instead (MiniLM, 384-d contextual per word, by default; any registered
  encoder works, the checkpoint records which).
* **Speaker** (§3.1.3): :func:`speaker_key` of the take name (BEAT2 names start with the speaker number; any other
  name is the single speaker ``"default"``); the speaker table is stored in the model config.
* **Poses** (§3.1.4): 9 unit edge directions over 10 joints (:data:`JOINTS`, :data:`EDGES`) from the canonical
  skeleton's forward kinematics, minus the training mean direction; back to canonical rotations by per-bone swings
  (:func:`directions_to_motion`).

Windows are ``seq_len`` = 34 frames (the paper's T); the first ``n_seed`` = 4 frames of the seed-pose input carry
known poses and the rest are zero with a "known" flag of 0 (the released Yoon et al. / S2AG code's way of feeding
"seed poses of length T"). Inference runs window after window, seeding each with the last 4 generated poses.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robogest.learn import config_with_overrides, require_torch

torch = require_torch("the 's2ag' generator")
nn = torch.nn
F = torch.nn.functional

from robogest.data.features import FeatureConfig, speech_inputs, text_encoder_for  # noqa: E402
from robogest.data.prep import slice_windows  # noqa: E402
from robogest.errors import InputError  # noqa: E402
from robogest.generators.base import Generator  # noqa: E402
from robogest.learn.checkpoint import build_model, load_checkpoint  # noqa: E402
from robogest.motion import rotations as R  # noqa: E402
from robogest.motion.human_motion import HumanMotion  # noqa: E402
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M  # noqa: E402
from robogest.speech.types import Speech  # noqa: E402

# ----------------------------------------------------------------------------------------------------------------
# Pose graph (§3.1.4)

#: The 10 upper-body joints as canonical joint names: root, spine, neck, head, then each arm's shoulder, elbow,
#: wrist. "spine" is ``spine2`` (where neck and collars attach); "head" is ``nose``, the head's tip, so the head's
#: nod and turn are part of the neck->head edge.
JOINTS = ("pelvis", "spine2", "neck", "nose", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist")
#: The 9 edges ``(source, destination)`` as indices into :data:`JOINTS`, directed from the root outwards.
EDGES = ((0, 1), (1, 2), (2, 3), (1, 4), (4, 5), (5, 6), (1, 7), (7, 8), (8, 9))
#: Edges of each body part for the second STGCN level: trunk, left arm, right arm.
BODY_PARTS = ((0, 1, 2), (3, 4, 5), (6, 7, 8))
N_EDGES = len(EDGES)
#: Frames each side of a frame in the temporal neighbourhood of both STGCN levels (§3.1.4: "past two and future two").
TEMPORAL_REACH = 2
#: Correction rounds for the two-bone trunk in :func:`directions_to_motion`.
TRUNK_ITERATIONS = 4


def edge_adjacency(hops: int = 2) -> np.ndarray:
    """Level-1 spatial adjacency ``A1`` over the 9 edges, self loops included.

    Two edges are adjacent when they share a vertex (1 hop) or both touch the ends of a third edge (2 hops): the
    distance in the line graph of the joint tree is at most ``hops``.

    Returns
    -------
    ndarray [shape=(9, 9)], {0, 1}
    """
    share = np.array([[bool(set(a) & set(b)) for b in EDGES] for a in EDGES], dtype=np.int64)  # (9, 9) line graph
    reach = np.eye(N_EDGES, dtype=np.int64)
    for _ in range(hops):
        reach = ((reach @ share) > 0).astype(np.int64)
    return reach.astype(np.float32)


def part_adjacency() -> np.ndarray:
    """Level-2 adjacency ``A2`` over (trunk, left arm, right arm): arms touch the trunk, not each other; self loops.

    Returns
    -------
    ndarray [shape=(3, 3)], {0, 1}
    """
    return np.array([[1, 1, 1], [1, 1, 0], [1, 0, 1]], dtype=np.float32)


def _rest_positions() -> np.ndarray:
    rest = np.tile(R.IDENTITY, (1, CANONICAL.n_joints, 1))  # (1, J, 4)
    return CANONICAL.forward_kinematics(rest, np.zeros((1, 3)))[0]  # (J, 3)


_IDX = [CANONICAL.index(n) for n in JOINTS]
_REST = _rest_positions()
#: Bone length ``b_i`` of each edge in the canonical rest pose, metres (eq. 11).
BONE_LENGTHS = np.array([np.linalg.norm(_REST[_IDX[d]] - _REST[_IDX[s]]) for s, d in EDGES])


def positions_to_directions(pos: np.ndarray) -> np.ndarray:
    """Joint positions ``(..., 10, 3)`` (the :data:`JOINTS`) -> unit edge directions ``(..., 9, 3)``."""
    src, dst = [s for s, _ in EDGES], [d for _, d in EDGES]
    v = pos[..., dst, :] - pos[..., src, :]  # (..., 9, 3)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def motion_to_directions(motion: HumanMotion) -> np.ndarray:
    """Canonical motion -> unit edge directions ``(T, 9, 3)`` in the world frame (Y up, facing +Z)."""
    pos = motion.skeleton.forward_kinematics(motion.rotations, motion.root_pos_m)  # (T, J, 3)
    return positions_to_directions(pos[:, _IDX])


def expmaps_to_directions(poses: np.ndarray) -> np.ndarray:
    """Canonical exponential maps ``(T, J * 3)`` (a take's poses) -> unit edge directions ``(T, 9, 3)``."""
    rot = R.from_axis_angle(np.asarray(poses, np.float64).reshape(poses.shape[0], CANONICAL.n_joints, 3))  # (T,J,4)
    pos = CANONICAL.forward_kinematics(rot, np.zeros((poses.shape[0], 3)))  # (T, J, 3)
    return positions_to_directions(pos[:, _IDX])


def directions_to_positions(dirs: np.ndarray, lengths: np.ndarray = BONE_LENGTHS, root=None) -> np.ndarray:
    """Eq. 11: scale each direction to its bone length and chain from the root.

    Parameters
    ----------
    dirs : ndarray [shape=(T, 9, 3)]
        Edge vectors (normalised here).
    lengths : ndarray [shape=(9,)], metres
    root : ndarray [shape=(3,)], optional
        Root position (default: the origin).

    Returns
    -------
    ndarray [shape=(T, 10, 3)], metres
    """
    u = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-9)
    pos = np.zeros((dirs.shape[0], len(JOINTS), 3))
    if root is not None:
        pos[:, 0] = root
    for i, (s, d) in enumerate(EDGES):  # EDGES lists every source before its destinations
        pos[:, d] = pos[:, s] + lengths[i] * u[:, i]
    return pos


def _swing(parent_global: np.ndarray, offset: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Local rotation (``(T, 4)``) turning bone ``offset`` from where the parent frame points it to ``target``."""
    cur = R.rotate(parent_global, np.broadcast_to(offset, target.shape))  # (T, 3)
    return R.normalize(R.mul(R.conj(parent_global), R.mul(R.between(cur, target), parent_global)))


def directions_to_motion(dirs: np.ndarray, fps: float) -> HumanMotion:
    """Unit edge directions ``(T, 9, 3)`` -> canonical :class:`HumanMotion` (for the shared retargeting).

    Each edge's swing (the smallest rotation from where the bone points with an identity local rotation to the
    target direction) goes into the canonical joint that moves it: ``spine2``/``neck``/collar/shoulder/elbow for
    their edges; the root->spine edge spans three canonical bones and its swing is split in two equal halves over
    ``spine`` and ``spine1`` (corrected iteratively for the fixed pelvis->spine offset); the collar is aimed so the
    shoulder lies on the ray of its edge. Approximations: twist about a bone is not represented (zero twist out),
    the pelvis, head, wrists and hands keep identity local rotations (so the hands' orientation is lost, the
    head's follows the neck), and edge lengths are the canonical ones. The root stays at its rest position.
    """
    dirs = np.asarray(dirs, np.float64)
    t = dirs.shape[0]
    u = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-9)
    off = CANONICAL.offsets_m
    ix = CANONICAL.index
    local = np.tile(R.IDENTITY, (t, CANONICAL.n_joints, 1))  # (T, J, 4)
    ident = np.tile(R.IDENTITY, (t, 1))  # (T, 4)
    # trunk: pelvis -> spine2 over spine and spine1 (the pelvis->spine offset is fixed with an identity pelvis);
    # the swing is split in halves and corrected a few times, since the fixed first offset bends less
    o_spine, o_spine1, o_spine2 = off[ix("spine")], off[ix("spine1")], off[ix("spine2")]
    total = R.between(np.tile(o_spine1 + o_spine2, (t, 1)), u[:, 0])  # (T, 4)
    for _ in range(TRUNK_ITERATIONS):
        half = R.slerp(ident, total, 0.5)  # (T, 4)
        reached = o_spine + R.rotate(half, o_spine1) + R.rotate(R.mul(half, half), o_spine2)  # (T, 3)
        total = R.normalize(R.mul(R.between(reached, u[:, 0]), total))
    half = R.slerp(ident, total, 0.5)
    local[:, ix("spine")] = half
    local[:, ix("spine1")] = half
    g_spine1 = R.mul(half, half)
    local[:, ix("spine2")] = _swing(g_spine1, off[ix("neck")], u[:, 1])
    g_spine2 = R.mul(g_spine1, local[:, ix("spine2")])
    # head edge neck -> nose: the neck carries the swing, the head keeps identity
    local[:, ix("neck")] = _swing(g_spine2, off[ix("head")] + off[ix("nose")], u[:, 2])
    p_spine2 = o_spine + R.rotate(half, o_spine1) + R.rotate(g_spine1, o_spine2)
    for side, e_sh, e_el, e_wr in (("l", 3, 4, 5), ("r", 6, 7, 8)):
        collar, shoulder, elbow, wrist = (ix(f"{side}_{n}") for n in ("collar", "shoulder", "elbow", "wrist"))
        p_collar = p_spine2 + R.rotate(g_spine2, off[collar])  # (T, 3)
        # the shoulder goes where the edge's ray from spine2 meets the collar bone's sphere: |w + λu| = |offset|
        w = p_spine2 - p_collar  # (T, 3)
        wu = np.sum(w * u[:, e_sh], axis=-1)  # (T,)
        disc = wu**2 - np.sum(w * w, axis=-1) + np.sum(off[shoulder] ** 2)
        lam = -wu + np.sqrt(np.maximum(disc, 0.0))  # (T,), metres along the ray
        target = w + lam[:, None] * u[:, e_sh]  # collar -> wanted shoulder position
        local[:, collar] = _swing(g_spine2, off[shoulder], target)
        g = R.mul(g_spine2, local[:, collar])
        local[:, shoulder] = _swing(g, off[elbow], u[:, e_el])
        g = R.mul(g, local[:, shoulder])
        local[:, elbow] = _swing(g, off[wrist], u[:, e_wr])
    root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (t, 1))  # (T, 3)
    return HumanMotion(fps=fps, rotations=R.normalize(local), root_pos_m=root, skeleton=CANONICAL)


# ----------------------------------------------------------------------------------------------------------------
# Inputs


def mfcc_from_mel(mel_db: np.ndarray) -> np.ndarray:
    """The speech front-end's 37 MFCC values from its log-mel spectrum (``SpeechFeatures.mfcc`` layout).

    ``librosa.feature.mfcc(S=mel_db)`` is an orthonormal DCT-II over the mel bands; taking it here lets training
    use the cached mel features (the frame-grid interpolation is linear, so the order does not matter).

    Parameters
    ----------
    mel_db : ndarray [shape=(T, 64)], dB

    Returns
    -------
    ndarray [shape=(T, 37)]
        c0..c12, forward differences of c1..c12, their forward differences (last rows 0).
    """
    from scipy.fft import dct

    from robogest.speech.features import N_MFCC, forward_diff

    cep = dct(np.asarray(mel_db, np.float64), type=2, norm="ortho", axis=1)[:, :N_MFCC]  # (T, 13)
    d1 = forward_diff(cep[:, 1:])  # (T, 12)
    return np.concatenate([cep, d1, forward_diff(d1)], axis=1).astype(np.float32)  # (T, 37)


_SPEAKER_RE = re.compile(r"^(\d+)_")


def speaker_key(take_name: str) -> str:
    """Speaker of a take from its name: BEAT2's leading speaker number (``"2_scott_0_1_1"`` -> ``"2"``), else
    ``"default"`` (GENEA/Trinity and plain folders hold one speaker)."""
    m = _SPEAKER_RE.match(take_name)
    return m.group(1) if m else "default"


# ----------------------------------------------------------------------------------------------------------------
# Model


@dataclass(frozen=True)
class S2AGConfig:
    """Hyper-parameters (Table 1, §4) and the data statistics a checkpoint needs.

    Attributes
    ----------
    n_mfcc, n_text : int
        MFCC values (37) and text-vector size per frame (384 for MiniLM).
    speakers : tuple of str
        Speaker keys (:func:`speaker_key`) in one-hot order; ``len`` is S.
    seq_len, n_seed : int
        Window length T in frames (34) and known seed frames at its start (4).
    d_mfcc, d_text, d_style : int
        D_m = 32, D_x = 32, D_s = 16.
    d_aff1, d_aff2, d_aff : int
        D_a1 = D_a2 = D_a = 16.
    d_gen, d_disc : int
        GRU widths D_e = D_d = 150.
    gru_layers : int
        Layers of both bidirectional GRUs.
    dropout : float
        Between GRU layers.
    lr_generator, lr_discriminator, beta1 : float
        Adam settings (5e-4, 1e-4, 0.5; §4); ``robogest train --lr`` does not apply to this model.
    w_huber, w_gan, w_div, w_kld : float
        Loss weights λ (eq. 15), Yoon et al.'s values (500, 5, 0.05, 0.1).
    huber_beta : float
        Huber transition point on the direction vectors (0.1, Yoon et al.).
    mfcc_mean, mfcc_std : tuple of float
        MFCC normalisation from the training takes (37 each; empty until fitted).
    dir_mean : tuple of float
        Mean unit edge direction (27), subtracted from the model's pose space.
    """

    n_mfcc: int = 37
    n_text: int = 384
    speakers: tuple[str, ...] = ("default",)
    seq_len: int = 34
    n_seed: int = 4
    d_mfcc: int = 32
    d_text: int = 32
    d_style: int = 16
    d_aff1: int = 16
    d_aff2: int = 16
    d_aff: int = 16
    d_gen: int = 150
    d_disc: int = 150
    gru_layers: int = 2
    dropout: float = 0.1
    lr_generator: float = 5e-4
    lr_discriminator: float = 1e-4
    beta1: float = 0.5
    w_huber: float = 500.0
    w_gan: float = 5.0
    w_div: float = 0.05
    w_kld: float = 0.1
    huber_beta: float = 0.1
    mfcc_mean: tuple[float, ...] = ()
    mfcc_std: tuple[float, ...] = ()
    dir_mean: tuple[float, ...] = ()

    @property
    def n_speakers(self) -> int:
        return len(self.speakers)

    @property
    def n_input(self) -> int:
        """Columns of a training window's speech array: normalised MFCC, text, speaker index."""
        return self.n_mfcc + self.n_text + 1

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> S2AGConfig:
        d = dict(d)
        for k in ("speakers", "mfcc_mean", "mfcc_std", "dir_mean"):
            if k in d:
                d[k] = tuple(d[k])
        return cls(**d)


class STGCNBlock(nn.Module):
    """Spatial graph convolution over a fixed adjacency, then a temporal convolution over ±2 frames (ST-GCN)."""

    def __init__(self, c_in: int, c_out: int, adjacency: np.ndarray) -> None:
        super().__init__()
        a = torch.as_tensor(adjacency, dtype=torch.float32)
        d = a.sum(1).rsqrt()
        self.register_buffer("adjacency", d[:, None] * a * d[None, :])  # (V, V), symmetric normalisation
        self.spatial = nn.Conv2d(c_in, c_out, 1)
        k = 2 * TEMPORAL_REACH + 1
        self.temporal = nn.Conv2d(c_out, c_out, (k, 1), padding=(TEMPORAL_REACH, 0))
        self.residual = nn.Identity() if c_in == c_out else nn.Conv2d(c_in, c_out, 1)
        self.act = nn.LeakyReLU(0.2)

    def forward(self, x):
        """``(B, C_in, T, V)`` -> ``(B, C_out, T, V)``."""
        y = torch.einsum("bctv,vw->bctw", self.spatial(x), self.adjacency)  # mix neighbouring vertices
        return self.act(self.temporal(self.act(y)) + self.residual(x))


class AffectiveEncoder(nn.Module):
    """§3.1.4: STGCN over the 9 edges, STGCN over the 3 body parts, 1-D convolutions -> ``(B, T, D_a)``."""

    def __init__(self, c_in: int, c: S2AGConfig) -> None:
        super().__init__()
        a1, a2 = edge_adjacency(), part_adjacency()
        self.level1 = nn.Sequential(STGCNBlock(c_in, c.d_aff1, a1), STGCNBlock(c.d_aff1, c.d_aff1, a1))
        self.level2 = STGCNBlock(3 * c.d_aff1, c.d_aff2, a2)
        self.conv = nn.Sequential(
            nn.Conv1d(3 * c.d_aff2, c.d_aff, 3, padding=1), nn.LeakyReLU(0.2), nn.Conv1d(c.d_aff, c.d_aff, 3, padding=1)
        )
        self.register_buffer("part_order", torch.tensor([e for part in BODY_PARTS for e in part]))

    def forward(self, x):
        """``x`` ``(B, T, 9, C_in)`` -> ``(B, T, D_a)``."""
        b, t = x.shape[:2]
        h = self.level1(x.permute(0, 3, 1, 2))  # (B, T, 9, C) -> (B, C, T, 9) -> (B, D_a1, T, 9)
        h = h[..., self.part_order].reshape(b, -1, t, 3, 3)  # (B, D_a1, T, part, edge-in-part)
        h = h.permute(0, 1, 4, 2, 3).reshape(b, -1, t, 3)  # (B, D_a1 * 3, T, part): part edges as features
        h = self.level2(h)  # (B, D_a2, T, 3)
        h = h.permute(0, 1, 3, 2).reshape(b, -1, t)  # (B, D_a2 * 3, T)
        return self.conv(h).transpose(1, 2)  # (B, D_a, T) -> (B, T, D_a)


class S2AGGeneratorNet(nn.Module):
    """§3.1: four encoders, Bi-GRU with summed directions (eq. 8-9), FC layers to 9 edge vectors (eq. 10)."""

    def __init__(self, c: S2AGConfig) -> None:
        super().__init__()
        self.config = c
        self.mfcc_conv = nn.Sequential(
            nn.Conv1d(c.n_mfcc, c.d_mfcc, 3, padding=1), nn.LeakyReLU(0.2),
            nn.Conv1d(c.d_mfcc, c.d_mfcc, 3, padding=1), nn.LeakyReLU(0.2),
        )  # fmt: skip
        self.mfcc_fc = nn.Linear(c.d_mfcc, c.d_mfcc)
        self.text_conv = nn.Sequential(
            nn.Conv1d(c.n_text, c.d_text, 3, padding=1), nn.LeakyReLU(0.2), nn.Conv1d(c.d_text, c.d_text, 3, padding=1)
        )
        self.speaker_fc = nn.Sequential(nn.Linear(c.n_speakers, c.d_style), nn.LeakyReLU(0.2))
        self.style_mu = nn.Linear(c.d_style, c.d_style)
        self.style_logvar = nn.Linear(c.d_style, c.d_style)
        self.affective = AffectiveEncoder(4, c)  # xyz + "known seed frame" flag
        d_in = c.d_mfcc + c.d_text + c.d_style + c.d_aff
        self.gru = nn.GRU(
            d_in,
            c.d_gen,
            c.gru_layers,
            batch_first=True,
            bidirectional=True,
            dropout=c.dropout if c.gru_layers > 1 else 0,
        )
        self.out = nn.Sequential(
            nn.Linear(c.d_gen, c.d_gen // 2), nn.LeakyReLU(0.2), nn.Linear(c.d_gen // 2, 3 * N_EDGES)
        )

    def style(self, speaker):
        """Speaker indices ``(B,)`` -> ``(mu, logvar)`` of the style distribution, ``(B, D_s)`` each (eq. 3-4)."""
        h = self.speaker_fc(F.one_hot(speaker, self.config.n_speakers).float())  # (B, S) -> (B, D_s)
        return self.style_mu(h), self.style_logvar(h)

    def forward(self, mfcc, text, seed, speaker=None, z=None):
        """Edge vectors of one window.

        Parameters
        ----------
        mfcc : Tensor [shape=(B, T, 37)]
            Normalised MFCC.
        text : Tensor [shape=(B, T, n_text)]
        seed : Tensor [shape=(B, T, 27)]
            Mean-subtracted directions; only the first ``n_seed`` frames are read.
        speaker : Tensor [shape=(B,)], int64, optional
            Style from the speaker's distribution: sampled (reparameterisation) in training mode, its mean in eval.
        z : Tensor [shape=(B, D_s)], optional
            A given style (overrides ``speaker``); neither: the prior mean 0.

        Returns
        -------
        out : Tensor [shape=(B, T, 27)]
            Mean-subtracted edge vectors.
        z, mu, logvar : Tensor [shape=(B, D_s)] (mu, logvar None without ``speaker``)
        """
        c = self.config
        b, t = mfcc.shape[:2]
        mu = logvar = None
        if speaker is not None:
            mu, logvar = self.style(speaker)
        if z is None:
            if mu is None:
                z = mfcc.new_zeros(b, c.d_style)
            elif self.training:
                z = mu + torch.randn_like(mu) * (0.5 * logvar).exp()  # reparameterisation trick
            else:
                z = mu
        fm = self.mfcc_fc(self.mfcc_conv(mfcc.transpose(1, 2)).transpose(1, 2))  # (B,37,T) -> (B,D_m,T) -> (B,T,D_m)
        fx = self.text_conv(text.transpose(1, 2)).transpose(1, 2)  # (B, D, T) -> (B, D_x, T) -> (B, T, D_x)
        fs = z[:, None].expand(b, t, c.d_style)  # (B, T, D_s): the style repeated over time
        known = torch.zeros(b, t, N_EDGES, 1, dtype=mfcc.dtype, device=mfcc.device)  # (B, T, 9, 1)
        known[:, : c.n_seed] = 1.0
        s = seed.reshape(b, t, N_EDGES, 3) * known  # (B, T, 27) -> (B, T, 9, 3), unknown frames zeroed
        fa = self.affective(torch.cat([s, known], dim=-1))  # (B, T, 9, 4) -> (B, T, D_a)
        h, _ = self.gru(torch.cat([fm, fx, fs, fa], dim=-1))  # (B, T, 2 * D_e)
        h = h[..., : c.d_gen] + h[..., c.d_gen :]  # eq. 9: forward + backward, (B, T, D_e)
        return self.out(h), z, mu, logvar  # (B, T, 27)


class S2AGDiscriminator(nn.Module):
    """§3.2: affective encoder, Bi-GRU (summed directions), FC per frame then over time -> one logit."""

    def __init__(self, c: S2AGConfig) -> None:
        super().__init__()
        self.config = c
        self.affective = AffectiveEncoder(3, c)
        self.gru = nn.GRU(
            c.d_aff, c.d_disc, c.gru_layers, batch_first=True, bidirectional=True,
            dropout=c.dropout if c.gru_layers > 1 else 0,
        )  # fmt: skip
        self.per_frame = nn.Linear(c.d_disc, 1)
        self.over_time = nn.Linear(c.seq_len, 1)

    def forward(self, dirs):
        """``(B, T, 27)`` mean-subtracted directions -> ``(B,)`` logits (sigmoid: probability of real)."""
        b, t = dirs.shape[:2]
        h, _ = self.gru(self.affective(dirs.reshape(b, t, N_EDGES, 3)))  # (B, T, 9, 3) -> (B, T, D_a) -> (B,T,2D_d)
        h = h[..., : self.config.d_disc] + h[..., self.config.d_disc :]  # eq. 13, (B, T, D_d)
        return self.over_time(self.per_frame(h)[..., 0])[:, 0]  # (B, T, 1) -> (B, T) -> (B, 1) -> (B,)


class S2AGNet(nn.Module):
    """Generator + discriminator in one module, so one state dict holds the GAN."""

    def __init__(self, config: S2AGConfig) -> None:
        super().__init__()
        self.config = config
        self.generator = S2AGGeneratorNet(config)
        self.discriminator = S2AGDiscriminator(config)

    def forward(self, *args, **kwargs):
        return self.generator(*args, **kwargs)


# ----------------------------------------------------------------------------------------------------------------
# Losses and the trainer's view


def split_batch(speech, c: S2AGConfig):
    """A window batch ``(B, T, 37 + n_text + 1)`` -> MFCC ``(B, T, 37)``, text ``(B, T, n_text)``, speaker ``(B,)``."""
    mfcc = speech[..., : c.n_mfcc]
    text = speech[..., c.n_mfcc : c.n_mfcc + c.n_text]
    speaker = speech[:, 0, -1].round().long()  # constant over a window
    return mfcc, text, speaker


def huber(pred, target, beta: float):
    """Huber (smooth L1) loss with transition ``beta``, scaled so it is ``|x|`` for large errors."""
    return F.smooth_l1_loss(pred / beta, target / beta) * beta


def kl_divergence(mu, logvar):
    """KL(N(mu, exp(logvar)) || N(0, I)), summed over dimensions, batch mean."""
    return (-0.5 * (1 + logvar - mu.pow(2) - logvar.exp()).sum(-1)).mean()


def diversity_regulariser(gen, mfcc, text, poses, speaker, out, z):
    """Yoon et al.'s style diversity term: minus motion difference per style difference, for shuffled speakers."""
    perm = torch.randperm(speaker.shape[0], device=speaker.device)
    out2, z2, _, _ = gen(mfcc, text, poses, speaker[perm])
    beta = 0.05
    pose_l1 = (F.smooth_l1_loss(out / beta, out2.detach() / beta, reduction="none") * beta).sum((1, 2))  # (B,)
    z_l1 = (z.detach() - z2.detach()).abs().mean(-1)  # (B,)
    return torch.clamp(-pose_l1 / (z_l1 + 1e-5), min=-1000.0).mean()


class S2AGSpec:
    """The trainer's view of the model (:class:`robogest.learn.trainer.ModelSpec` + its optional GAN methods)."""

    name = "s2ag"

    def make_config(self, n_acoustic: int, n_text: int, n_pose: int, overrides: dict[str, Any]) -> S2AGConfig:
        return config_with_overrides(S2AGConfig, "s2ag", overrides, n_text=n_text)

    def config_from_dict(self, d: dict[str, Any]) -> S2AGConfig:
        return S2AGConfig.from_dict(d)

    def fit_config(self, config: S2AGConfig, takes: Sequence[Any]) -> S2AGConfig:
        """Speaker table, MFCC statistics and mean direction from the training takes."""
        mfcc = np.concatenate([mfcc_from_mel(t.acoustic[:, :64]) for t in takes]).astype(np.float64)  # (ΣT, 37)
        dirs = np.concatenate([expmaps_to_directions(t.poses) for t in takes]).reshape(-1, 3 * N_EDGES)  # (ΣT, 27)
        std = mfcc.std(0)
        std = np.where(std < 1e-4, 1.0, std)
        return dataclasses.replace(
            config,
            speakers=tuple(sorted({speaker_key(t.name) for t in takes})),
            mfcc_mean=tuple(map(float, mfcc.mean(0))),
            mfcc_std=tuple(map(float, std)),
            dir_mean=tuple(map(float, dirs.mean(0))),
        )

    def make_windows(self, takes, norm, config: S2AGConfig, length: int, stride: int):
        """Windows of ``[normalised MFCC | text | speaker index]`` ``(N, L, 37 + D + 1)`` and mean-subtracted
        directions ``(N, L, 27)``; the trainer's exp-map normalisation ``norm`` is not used."""
        table = {s: i for i, s in enumerate(config.speakers)}
        mean, std = np.asarray(config.mfcc_mean, np.float32), np.asarray(config.mfcc_std, np.float32)

        def take_arrays(t) -> tuple[np.ndarray, np.ndarray]:
            mfcc = (mfcc_from_mel(t.acoustic[:, :64]) - mean) / std  # (T, 37)
            spk = np.full((t.n_frames, 1), table.get(speaker_key(t.name), 0), np.float32)  # unseen speaker -> 0
            x = np.concatenate([mfcc, t.text, spk], axis=1)  # (T, 37 + D + 1)
            y = expmaps_to_directions(t.poses).reshape(t.n_frames, -1) - np.asarray(config.dir_mean)  # (T, 27)
            return x, y

        per_take = ((i, *take_arrays(t)) for i, t in enumerate(takes) if t.n_frames >= length)
        return slice_windows(per_take, length, stride, config.n_input, 3 * N_EDGES)

    def build(self, config: S2AGConfig) -> S2AGNet:
        return S2AGNet(config)

    def sequence_length(self, config: S2AGConfig) -> int:
        return config.seq_len

    def make_optimizers(self, model: S2AGNet, train_config: Any, config: S2AGConfig) -> dict[str, Any]:
        """Adam, β = (0.5, 0.999), 5e-4 for the generator and 1e-4 for the discriminator (§4)."""
        betas = (config.beta1, 0.999)
        return {
            "generator": torch.optim.Adam(model.generator.parameters(), lr=config.lr_generator, betas=betas),
            "discriminator": torch.optim.Adam(
                model.discriminator.parameters(), lr=config.lr_discriminator, betas=betas
            ),
        }

    def loss(self, model, speech, poses, epoch: int, config: S2AGConfig):
        """Huber reconstruction of the edge vectors (the validation loss; styles at their means in eval mode)."""
        gen = _unwrap(model).generator
        mfcc, text, speaker = split_batch(speech, config)
        out, _, _, _ = gen(mfcc, text, poses, speaker)
        return huber(out, poses, config.huber_beta)

    def discriminator_step(self, model, opt, fake, real) -> float:
        """One D update on generated ``fake`` and ``real`` ``(B, T, 27)``; eq. 16 as binary cross-entropy."""
        disc = _unwrap(model).discriminator
        lr, lf = disc(real), disc(fake.detach())
        loss = F.binary_cross_entropy_with_logits(lr, torch.ones_like(lr)) + F.binary_cross_entropy_with_logits(
            lf, torch.zeros_like(lf)
        )
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return float(loss.detach())

    def generator_step(self, model, opt, speech, poses, config: S2AGConfig) -> dict[str, float]:
        """One G update with eq. 15 (discriminator weights untouched: only G's optimiser steps)."""
        net = _unwrap(model)
        gen, disc = net.generator, net.discriminator
        mfcc, text, speaker = split_batch(speech, config)
        out, z, mu, logvar = gen(mfcc, text, poses, speaker)
        rec = huber(out, poses, config.huber_beta)
        lf = disc(out)
        adv = F.binary_cross_entropy_with_logits(lf, torch.ones_like(lf))  # eq. 17: -log D(G)
        div = diversity_regulariser(gen, mfcc, text, poses, speaker, out, z)
        kld = kl_divergence(mu, logvar)
        total = config.w_huber * rec + config.w_gan * adv + config.w_div * div + config.w_kld * kld
        opt.zero_grad(set_to_none=True)
        total.backward()
        opt.step()
        return {"huber": float(rec.detach()), "g_adv": float(adv.detach()), "div": float(div.detach()),
                "kld": float(kld.detach()), "g_total": float(total.detach()), "fake": out.detach()}  # fmt: skip

    def train_step(self, model, optimizers, speech, poses, epoch: int, config: S2AGConfig) -> dict[str, float]:
        """Generator step (eq. 15), then a discriminator step (eq. 16) on that batch's generated gestures."""
        g = self.generator_step(model, optimizers["generator"], speech, poses, config)
        fake = g.pop("fake")
        g["d_loss"] = self.discriminator_step(model, optimizers["discriminator"], fake, poses)
        g["loss"] = g["huber"]
        return g


def _unwrap(model):
    return model.module if hasattr(model, "module") else model


SPEC = S2AGSpec()


# ----------------------------------------------------------------------------------------------------------------
# Generator


class S2AGGenerator(Generator):
    """Generator backed by a checkpoint from ``robogest train --model s2ag``.

    Parameters
    ----------
    checkpoint : path-like
        ``.pt`` file (model config with speaker table and statistics, feature config).
    speaker : None, int, "sample" or array-like of shape (D_s,)
        Style: ``None`` the training speakers' average style (mean of their means); an int that speaker's mean
        style; ``"sample"`` a new style drawn from N(0, I) with ``generate``'s seed; a vector a given style (e.g.
        an interpolation of :meth:`style_vector` results).
    device : str
        Torch device for inference.
    encoder : TextEncoder, optional
        Overrides the text encoder the checkpoint names (same dimension).
    """

    name = "s2ag"

    def __init__(
        self, checkpoint: str | os.PathLike | None = None, speaker: Any = None, device: str = "cpu", encoder=None
    ) -> None:
        if checkpoint is None:
            raise InputError(
                "the s2ag generator needs --checkpoint FILE.pt; train one with "
                "`robogest train --model s2ag --data DIR --out DIR`"
            )
        ckpt = load_checkpoint(checkpoint, map_location=device)
        if ckpt["model_name"] != "s2ag":
            raise InputError(f"{checkpoint}: a {ckpt['model_name']!r} checkpoint, not an s2ag one")
        config = S2AGConfig.from_dict(ckpt["model_config"])
        model = build_model(ckpt, lambda: S2AGNet(config), checkpoint, device)
        self._setup(model, FeatureConfig.from_dict(ckpt["feature_config"]), speaker, encoder)
        self.path = Path(checkpoint)

    @classmethod
    def from_model(cls, model: S2AGNet, features: FeatureConfig, speaker: Any = None, encoder=None) -> S2AGGenerator:
        """Wrap an in-memory model (tests, notebooks) without a checkpoint file."""
        self = cls.__new__(cls)
        self._setup(model, features, speaker, encoder)
        self.path = None
        return self

    def _setup(self, model: S2AGNet, features: FeatureConfig, speaker: Any, encoder) -> None:
        self.model = model.eval()
        self.config: S2AGConfig = model.config
        self.features = features
        self.device = next(model.parameters()).device
        self._encoder = encoder
        if not self.config.mfcc_mean or not self.config.dir_mean:
            raise InputError("the s2ag model config has no data statistics (it was never fitted to a dataset)")
        self.speaker = speaker
        self.style_vector(speaker, 0)  # validate now, not at the first generate

    @property
    def encoder(self):
        if self._encoder is None:
            self._encoder = text_encoder_for(self.features)
        if self._encoder.dim != self.config.n_text:
            raise InputError(f"text encoder gives {self._encoder.dim}-d vectors, the model needs {self.config.n_text}")
        return self._encoder

    def style_vector(self, speaker: Any = None, seed: int = 0) -> np.ndarray:
        """The style ``z`` ``(D_s,)`` that ``speaker`` (see the class) stands for."""
        c = self.config
        if isinstance(speaker, str) and speaker == "sample":
            g = torch.Generator().manual_seed(int(seed))
            return torch.randn(c.d_style, generator=g).numpy()
        with torch.inference_mode():
            if speaker is None:
                mu, _ = self.model.generator.style(torch.arange(c.n_speakers, device=self.device))  # (S, D_s)
                return mu.mean(0).cpu().numpy()
            if isinstance(speaker, (int, np.integer)) and not isinstance(speaker, bool):
                if not 0 <= int(speaker) < c.n_speakers:
                    raise InputError(f"speaker {speaker} out of range: the model knows {c.n_speakers} ({c.speakers})")
                mu, _ = self.model.generator.style(torch.tensor([int(speaker)], device=self.device))
                return mu[0].cpu().numpy()
        z = np.asarray(speaker, dtype=np.float32)
        if z.shape != (c.d_style,):
            raise InputError(f"speaker must be None, an int, 'sample' or a {c.d_style}-vector, got {speaker!r}")
        return z

    def inputs(self, speech: Speech) -> tuple[np.ndarray, np.ndarray]:
        """Normalised MFCC ``(T, 37)`` and text vectors ``(T, n_text)`` (re-analysed when the fps differs)."""
        if abs(speech.fps - self.features.fps) > 1e-6:
            from robogest.speech import analyze

            speech = analyze(speech.audio, speech.sr, speech.words, self.features.speech_config(), source=speech.source)
        _, text = speech_inputs(speech, self.features, self.encoder)  # (T, D)
        c = self.config
        mfcc = (speech.features.mfcc - np.asarray(c.mfcc_mean, np.float32)) / np.asarray(c.mfcc_std, np.float32)
        return mfcc.astype(np.float32), text.astype(np.float32)

    def predict(self, mfcc: np.ndarray, text: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Unit edge directions ``(T, 9, 3)`` for normalised inputs, window after window.

        Window ``k`` covers frames ``[k s, k s + T)`` with ``s = T - n_seed``; its seed is the previous window's
        last ``n_seed`` poses (the first window's is the mean pose). Inputs are padded with their last frame.
        """
        c = self.config
        n = mfcc.shape[0]
        if n == 0:
            return np.zeros((0, N_EDGES, 3), np.float32)
        step = c.seq_len - c.n_seed
        n_win = max(1, math.ceil((n - c.n_seed) / step))
        total = c.n_seed + n_win * step
        pad = np.minimum(np.arange(total), n - 1)  # edge padding
        x_m = torch.from_numpy(mfcc[pad]).to(self.device)  # (total, 37)
        x_t = torch.from_numpy(text[pad]).to(self.device)  # (total, D)
        zt = torch.from_numpy(np.asarray(z, np.float32)).to(self.device)[None]  # (1, D_s)
        seed = torch.zeros(1, c.seq_len, 3 * N_EDGES, device=self.device)  # mean pose
        outs = []
        with torch.inference_mode():
            for k in range(n_win):
                s = k * step
                out, _, _, _ = self.model.generator(
                    x_m[None, s : s + c.seq_len], x_t[None, s : s + c.seq_len], seed, z=zt
                )  # (1, T, 27)
                outs.append(out[0] if k == 0 else out[0, c.n_seed :])
                seed = torch.zeros_like(seed)
                seed[:, : c.n_seed] = out[:, -c.n_seed :]
        y = torch.cat(outs)[:n].cpu().numpy() + np.asarray(c.dir_mean, np.float32)  # (n, 27)
        y = y.reshape(n, N_EDGES, 3)  # (n, 27) -> (n, 9, 3)
        return (y / np.maximum(np.linalg.norm(y, axis=-1, keepdims=True), 1e-9)).astype(np.float32)

    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion at ``speech.fps`` lasting as long as the speech; ``seed`` only matters for ``speaker="sample"``."""
        torch.manual_seed(seed)
        mfcc, text = self.inputs(speech)
        dirs = self.predict(mfcc, text, self.style_vector(self.speaker, seed))  # (T, 9, 3)
        return directions_to_motion(dirs, self.features.fps).resample(speech.fps, n_frames=speech.n_frames)


__all__ = [
    "BODY_PARTS",
    "BONE_LENGTHS",
    "EDGES",
    "JOINTS",
    "SPEC",
    "AffectiveEncoder",
    "S2AGConfig",
    "S2AGDiscriminator",
    "S2AGGenerator",
    "S2AGGeneratorNet",
    "S2AGNet",
    "S2AGSpec",
    "directions_to_motion",
    "directions_to_positions",
    "edge_adjacency",
    "expmaps_to_directions",
    "mfcc_from_mel",
    "motion_to_directions",
    "part_adjacency",
    "speaker_key",
]
