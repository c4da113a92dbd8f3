"""refine()'s result in the kind, dtype and device of its input, unchanged frames exactly as given.

The pipeline works on a float32 copy. A float64 (or float16, bfloat16) input would come back with
every frame rounded through float32, so "frames that were not flagged come back exactly as given"
would fail by 1e-9; here the frames the pipeline left alone are taken from the input itself.
"""
from __future__ import annotations

import warnings

import numpy as np

__all__ = ["like_input"]


def like_input(out: np.ndarray, seq, x: np.ndarray):
    """``out`` as the kind of ``seq``: a torch tensor (same dtype and device) or a numpy array.

    Parameters
    ----------
    out : ndarray of shape (T, J, 3) or (B, T, J, 3), float32
        The refined joints.
    seq : array-like
        What the user passed (numpy, torch or nested lists).
    x : ndarray, float32
        ``seq`` as the float32 array the pipeline refined; frames where ``out`` equals it are unchanged.

    Returns
    -------
    ndarray or torch.Tensor
        Floating inputs keep their dtype, and their unchanged frames are copied bit for bit from
        ``seq``; other inputs (integers, lists) give float32. A tensor that requires grad comes back
        detached, with a ``UserWarning`` (refinement is not differentiable).
    """
    unchanged = (out == x).reshape(*out.shape[:-2], -1).all(-1)  # (T,) or (B, T)
    if not hasattr(seq, "detach"):
        if not isinstance(seq, np.ndarray) or not np.issubdtype(seq.dtype, np.floating) or seq.dtype == np.float32:
            return out
        result = out.astype(seq.dtype)
        result[unchanged] = seq[unchanged]
        return result
    import torch

    if seq.requires_grad:
        warnings.warn("refine() is not differentiable: the tensor it returns is detached from the graph of "
                      "`seq` (pass seq.detach() to silence this warning).", UserWarning, stacklevel=4)
    if not seq.dtype.is_floating_point or seq.dtype == torch.float32:
        return torch.from_numpy(out).to(seq.device)
    original = seq.detach().cpu()
    result = torch.from_numpy(out).to(seq.dtype)
    keep = torch.from_numpy(unchanged)
    result[keep] = original[keep]
    return result.to(seq.device)
