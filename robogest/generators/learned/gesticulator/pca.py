"""Gesticulator's optional PCA output space (Kucherenko et al. 2020, §5.1 and Table 2 "No PCA").

The paper reduces the exponential-map poses with PCA keeping 95 % of the training data's variance (12 components
on Trinity) and the model predicts the PCA coefficients; its final model drops the PCA (participants preferred it,
§6.2), which is why the option is off by default (``--set pca_variance=0.95`` turns it on). Here the PCA is fitted
on the *normalised* training poses, the space the loss is computed in: with orthonormal components the loss on
the reconstructed poses equals the loss on the coefficients up to a constant (the targets' residual outside the
subspace) and a scale, so training is that of the paper's coefficient-space model.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from robogest.errors import InputError


def fit_pose_pca(chunks: Iterable[np.ndarray], variance: float) -> tuple[npt.NDArray[np.float64], float]:
    """Principal axes of the rows of ``chunks`` that keep at least ``variance`` of their total variance.

    Parameters
    ----------
    chunks : iterable of ndarray [shape=(T_i, P)]
        Normalised training poses, one take at a time (one chunk in memory at a time).
    variance : float
        Fraction of the variance to keep, in (0, 1].

    Returns
    -------
    components : ndarray [shape=(K, P)], float64
        Orthonormal rows, largest variance first; ``K`` is the fewest that keep ``variance``.
    kept : float
        The fraction of the variance the ``K`` components keep (>= ``variance``).
    """
    if not 0.0 < variance <= 1.0:
        raise InputError(f"pca_variance={variance}: the fraction of variance to keep must be in (0, 1]")
    n, total, gram = 0, None, None
    for chunk in chunks:
        x = np.asarray(chunk, dtype=np.float64)  # (T_i, P)
        total = x.sum(0) if total is None else total + x.sum(0)
        gram = x.T @ x if gram is None else gram + x.T @ x
        n += x.shape[0]
    if n < 2 or total is None or gram is None:
        raise InputError("fitting the PCA needs at least two training poses")
    mean = total / n
    cov = (gram - n * np.outer(mean, mean)) / (n - 1)  # (P, P)
    eigval, eigvec = np.linalg.eigh(cov)  # ascending
    eigval, eigvec = np.clip(eigval[::-1], 0.0, None), eigvec[:, ::-1]
    if eigval.sum() <= 0:
        raise InputError("the training poses do not vary: no PCA can be fitted (turn pca_variance off)")
    ratio = np.cumsum(eigval) / eigval.sum()  # (P,)
    k = int(np.searchsorted(ratio, variance - 1e-12) + 1)
    k = min(k, eigval.size)
    return np.ascontiguousarray(eigvec[:, :k].T), float(ratio[k - 1])


def variance_kept(components: np.ndarray, poses: np.ndarray) -> float:
    """Fraction of the variance of ``poses`` ``(T, P)`` that projecting on ``components`` ``(K, P)`` keeps."""
    x = np.asarray(poses, dtype=np.float64)
    x = x - x.mean(0)
    c = np.asarray(components, dtype=np.float64)
    return float(np.sum((x @ c.T) ** 2) / np.sum(x**2))
