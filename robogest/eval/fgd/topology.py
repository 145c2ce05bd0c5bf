"""The SMPL-X skeleton graph of the BEAT2/EMAGE FGD evaluator: edges, neighbourhoods and pooling (no torch).

The evaluator (EMAGE's ``VAESKConv``, weights ``AESKConv_240_100.bin``) is a skeleton-aware convolutional encoder
in the style of Aberman et al. 2020 ("Skeleton-aware networks for deep motion retargeting"): its channels are
grouped per skeleton *edge*, each convolution only mixes edges within graph distance 2, and every layer pools
chains of edges pairwise. Everything here is derived from the SMPL-X kinematic tree, as the reference derives it
from ``kintree_table`` of ``SMPLX_NEUTRAL_2020.npz``; the state-dict masks and pooling matrices of the official
file must equal what this module computes (the loader checks them), which is how a mismatch is caught.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Parent of each of the 55 SMPL-X joints (pelvis, legs, spine, neck, head, arms, jaw, eyes, 2 x 15 finger joints).
SMPLX_PARENTS: tuple[int, ...] = (
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19,  # body
    15, 15, 15,  # jaw, left eye, right eye
    20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38,  # left hand: index, middle, pinky, ring, thumb
    21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53,  # right hand
)  # fmt: skip
N_JOINTS = len(SMPLX_PARENTS)

#: Hyper-parameters of the published evaluator (EMAGE ``emage_evaltools``: ``vae_length``, ``vae_layer``,
#: ``vae_grow``, ``vae_test_dim``, ``vae_test_len`` and the encoder's fixed settings).
LATENT_DIM = 240  # vae_length: channels of a latent frame
N_LAYERS = 4  # vae_layer
GROW = (1, 1, 2, 1)  # vae_grow: channel multiplier per layer
CHANNELS_PER_EDGE = 6  # channel_base: one rot6d per joint
INPUT_DIM = N_JOINTS * CHANNELS_PER_EDGE  # vae_test_dim = 330
WINDOW = 32  # vae_test_len: sequences are cut to a multiple of this many frames
KERNEL = 4  # temporal kernel of every skeleton convolution, stride 2, padding 1
NEIGHBOUR_DISTANCE = 2  # skeleton_dist: edges within this graph distance feed each other
GROUPS = 10  # GroupNorm groups after each residual convolution
FPS = 30.0  # BEAT2 motion rate the evaluator was trained at
TIME_DOWNSAMPLING = 2**N_LAYERS  # one latent frame per 16 input frames


def smplx_edges(parents: tuple[int, ...] = SMPLX_PARENTS) -> list[tuple[int, int]]:
    """Edges ``(parent, child)``: edge 0 joins the root to a virtual joint ``len(parents)`` (it carries the root's
    own rotation), edge ``i`` joins joint ``i`` to its parent, so edge ``i`` carries joint ``i``'s rotation."""
    return [(0, len(parents))] + [(parents[i], i) for i in range(1, len(parents))]


def edge_distances(edges: list[tuple[int, int]]) -> np.ndarray:
    """Graph distance ``(E, E)`` between edges: 0 to itself, 1 to edges sharing a joint (shortest paths)."""
    e = len(edges)
    d = np.full((e, e), 100_000, dtype=np.int64)
    for i, a in enumerate(edges):
        for j, b in enumerate(edges):
            if i == j:
                d[i, j] = 0
            elif set(a) & set(b):
                d[i, j] = 1
    for k in range(e):  # Floyd-Warshall
        d = np.minimum(d, d[:, k : k + 1] + d[k : k + 1, :])
    return d


def neighbours(edges: list[tuple[int, int]], distance: int = NEIGHBOUR_DISTANCE) -> list[list[int]]:
    """For each edge, the (ascending) edges within ``distance`` of it, itself included."""
    d = edge_distances(edges)
    return [np.flatnonzero(row <= distance).tolist() for row in d]


def edge_chains(edges: list[tuple[int, int]]) -> list[list[int]]:
    """Edges cut into chains between branching joints and end effectors, in depth-first order from joint 0.

    A chain ends at a joint of degree 1 (an end effector) or of degree > 2 (a branch, other than the root); the
    children of a joint are visited in the order their edges appear in ``edges``.
    """
    degree: dict[int, int] = {}
    for a, b in edges:
        degree[a] = degree.get(a, 0) + 1
        degree[b] = degree.get(b, 0) + 1
    chains: list[list[int]] = []

    def walk(joint: int, chain: list[int]) -> None:
        if degree[joint] > 2 and joint != 0:
            chains.append(chain)
            chain = []
        if degree[joint] == 1:
            chains.append(chain)
            return
        for idx, (a, b) in enumerate(edges):
            if a == joint:
                walk(b, [*chain, idx])

    walk(0, [])
    return chains


def pool_groups(edges: list[tuple[int, int]], last: bool) -> tuple[list[list[int]], list[tuple[int, int]]]:
    """Which edges are averaged together by a skeleton pooling, and the pooled skeleton's edges.

    Each chain is pooled pairwise (an odd chain keeps its first edge alone); the last layer pools every chain to
    one edge (its new edges are not needed).

    Returns
    -------
    groups : list of list of int
        Input edge indices averaged into each output edge.
    new_edges : list of (int, int)
        Edges of the pooled skeleton (empty when ``last``).
    """
    groups: list[list[int]] = []
    new_edges: list[tuple[int, int]] = []
    for chain in edge_chains(edges):
        if last:
            groups.append(chain)
            continue
        if len(chain) % 2:
            groups.append([chain[0]])
            new_edges.append(edges[chain[0]])
            chain = chain[1:]
        for a, b in zip(chain[::2], chain[1::2], strict=True):
            groups.append([a, b])
            new_edges.append((edges[a][0], edges[b][1]))
    return groups, new_edges


@dataclass(frozen=True)
class LayerPlan:
    """One encoder layer: its skeleton, neighbourhoods, channel counts and pooling."""

    edges: list[tuple[int, int]]
    neighbours: list[list[int]]
    in_per_edge: int
    out_per_edge: int
    groups: list[list[int]]

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @property
    def in_channels(self) -> int:
        return self.in_per_edge * self.n_edges

    @property
    def out_channels(self) -> int:
        return self.out_per_edge * self.n_edges

    @property
    def pools(self) -> bool:
        """Whether the layer has a pooling matrix (the reference skips one that would keep every edge)."""
        return len(self.groups) != self.n_edges


def encoder_plan() -> list[LayerPlan]:
    """The four layers of the evaluator's encoder, derived from the SMPL-X tree as the reference derives them."""
    edges = smplx_edges()
    per_edge = [CHANNELS_PER_EDGE]
    for g in GROW:
        per_edge.append(per_edge[-1] * g)
    plan = []
    for i in range(N_LAYERS):
        groups, new_edges = pool_groups(edges, last=i == N_LAYERS - 1)
        plan.append(LayerPlan(edges, neighbours(edges), per_edge[i], per_edge[i + 1], groups))
        edges = new_edges
    return plan


def conv_mask(layer: LayerPlan, kernel: int) -> np.ndarray:
    """0/1 mask ``(C_out, C_in, kernel)`` of a skeleton convolution: output edge ``i`` sees only its neighbours."""
    mask = np.zeros((layer.out_channels, layer.in_channels, kernel), dtype=np.float32)
    ci, co = layer.in_per_edge, layer.out_per_edge
    for i, nb in enumerate(layer.neighbours):
        cols = [k * ci + c for k in nb for c in range(ci)]
        mask[i * co : (i + 1) * co, cols, :] = 1.0
    return mask


def pool_matrix(layer: LayerPlan) -> np.ndarray:
    """Averaging matrix ``(G * C, E * C)`` of a skeleton pooling (``C`` = output channels per edge)."""
    c = layer.out_per_edge
    w = np.zeros((len(layer.groups) * c, layer.n_edges * c), dtype=np.float32)
    for g, members in enumerate(layer.groups):
        for e in members:
            w[g * c + np.arange(c), e * c + np.arange(c)] = 1.0 / len(members)
    return w
