"""Cubic splines of one transition, per joint and axis (paper Eq. 1).

A transition spanning frames ``k..n`` (both anchors included, ``duration = n - k``) is written in
normalised time ``tau = (i - k) / duration`` in ``[0, 1]``, so that coefficients of transitions of
different lengths are comparable:

    P(tau) = a * tau**3 + b * tau**2 + c * tau + d        (a, b, c, d each (J, 3), metres)

Coefficients are stored as ``(4, J, 3)`` in the order ``a, b, c, d``. Works on numpy arrays and
torch tensors alike.
"""
from __future__ import annotations

import numpy as np

__all__ = ["spline_basis", "fit_spline", "eval_spline"]


def spline_basis(n_frames: int, xp=np, dtype=None):
    """``(n_frames, 4)`` matrix ``[tau**3, tau**2, tau, 1]`` with ``tau = linspace(0, 1, n_frames)``."""
    if xp is np:
        tau = np.linspace(0.0, 1.0, n_frames, dtype=dtype or np.float64)
        return np.stack([tau**3, tau**2, tau, np.ones_like(tau)], axis=-1)
    tau = xp.linspace(0.0, 1.0, n_frames, dtype=dtype)
    return xp.stack([tau**3, tau**2, tau, xp.ones_like(tau)], dim=-1)


def fit_spline(points) -> np.ndarray:
    """Least-squares cubic through a transition's frames.

    Parameters
    ----------
    points : ndarray of shape (L, J, 3), L >= 2
        Frames ``k..n`` of the transition, anchors included.

    Returns
    -------
    ndarray of shape (4, J, 3), float32
        Coefficients ``a, b, c, d``. With fewer than 4 frames the minimum-norm exact fit.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim < 2 or pts.shape[0] < 2:
        raise ValueError(f"`points` must have shape (L, ...) with L >= 2; got {pts.shape}.")
    basis = spline_basis(pts.shape[0])
    flat = pts.reshape(pts.shape[0], -1)
    coeffs, *_ = np.linalg.lstsq(basis, flat, rcond=None)
    return coeffs.reshape((4,) + pts.shape[1:]).astype(np.float32)


def eval_spline(coeffs, n_frames: int):
    """Frames of a transition from its coefficients.

    Parameters
    ----------
    coeffs : array of shape (..., 4, J, 3)
        numpy array or torch tensor.
    n_frames : int
        Frames to produce, ``duration + 1`` (both anchors included).

    Returns
    -------
    array of shape (..., n_frames, J, 3), same library and dtype as ``coeffs``.
    """
    if isinstance(coeffs, np.ndarray):
        basis = spline_basis(n_frames).astype(coeffs.dtype)
        return np.einsum("lk,...kjc->...ljc", basis, coeffs)
    import torch  # only for tensors: the numpy segmentation must not wait for torch to import

    basis = spline_basis(n_frames, xp=torch, dtype=coeffs.dtype).to(coeffs.device)
    return torch.einsum("lk,...kjc->...ljc", basis, coeffs)
