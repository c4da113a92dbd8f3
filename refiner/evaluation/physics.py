"""Physical plausibility metrics on joint positions: smoothness, foot skating, ground contact, bones, splices.

Every function takes a :class:`~refiner.core.motion.Motion`, or joint positions ``(T, J, 3)`` / ``(B, T, J, 3)``
in metres in a registered skeleton's frame, and returns SI units (m, m/s, m/s², m/s³); a batch gives
one value per clip. The vertical comes from :attr:`Skeleton.up` (HumanAct12 and UESTC are y **down**,
HumanML3D and CMU y up); *height* is the coordinate along it.

**Ground.** HumanAct12 gives no floor. Unless a ``ground`` height is passed, it is estimated per clip
as the lowest height any contact joint (ankles, feet, toes, heels) reaches over the clip,
:func:`ground_height` - the HumanML3D convention of putting the floor under the lowest foot. With that
estimate penetration is zero by construction for the feet, so to judge an edited clip pass the ground
of its source (``ground=ground_height(source)``), as ``motion-refiner bench flaws`` does.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d

from refiner.core.contact import contact_joints, foot_joints, heights
from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton
from refiner.core.validation import check_joints

__all__ = [
    "heights",
    "contact_joints",
    "foot_joints",
    "ground_height",
    "acceleration",
    "jerk",
    "acceleration_error",
    "foot_skating_ratio",
    "foot_skate_distance",
    "penetration",
    "floating",
    "bone_length_variation",
    "VelocityJump",
    "boundary_velocity_jump",
]

def _prepare(x, skeleton, fps, *, min_frames: int = 2):
    """``(B, T, J, 3)`` float64 array, Skeleton, fps and whether the input was a single clip."""
    if isinstance(x, Motion):
        skel, rate = x.skeleton_info, x.fps if fps is None else fps
        arr, single = x.joints[None].astype(np.float64), True
        if len(arr[0]) < min_frames:
            raise ValueError(f"`motion` is too short: needs at least {min_frames} frames; got {len(arr[0])}.")
    else:
        skel = get_skeleton(skeleton)
        raw = np.asarray(x.detach().cpu() if hasattr(x, "detach") else x)
        single = raw.ndim == 3
        check_joints(raw[None] if single else raw, name="joints", skeleton=skel, min_frames=min_frames, batched=True)
        arr = np.array(raw[None] if single else raw, dtype=np.float64)  # validated above; keep float64 precision
        rate = skel.fps if fps is None else fps
    if not (isinstance(rate, (int, float, np.number)) and np.isfinite(rate) and rate > 0):
        raise ValueError(f"`fps` must be a positive number; got {rate!r}.")
    return arr, skel, float(rate), single


def _out(values: np.ndarray, single: bool):
    return float(values[0]) if single else values


def _horizontal(x: np.ndarray, skel: Skeleton) -> np.ndarray:
    up = skel.up_vector
    return x - (x @ up)[..., None] * up


def ground_height(motion, *, skeleton: str | Skeleton = "humanact12", quantile: float = 0.0):
    """Per-clip ground estimate: the lowest height the contact joints reach.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Metres.
    skeleton : str or Skeleton, default="humanact12"
        Ignored for a Motion.
    quantile : float in [0, 1], default=0.0
        Quantile over frames of each frame's lowest contact-joint height; 0 is the minimum (the
        HumanML3D floor convention), a small positive value ignores a few outlier frames.

    Returns
    -------
    float, or ndarray of shape (B,)
        Height of the ground in metres along the up axis (see :func:`heights`).
    """
    if not 0.0 <= quantile <= 1.0:
        raise ValueError(f"`quantile` must be in [0, 1]; got {quantile!r}.")
    x, skel, _, single = _prepare(motion, skeleton, None, min_frames=1)
    low = heights(x[..., list(contact_joints(skel)), :], skel).min(-1)  # (B, T)
    return _out(np.quantile(low, quantile, axis=1), single)


def _ground(x, skel, ground) -> np.ndarray:
    """``(B,)`` ground heights: the given one(s) or the per-clip estimate."""
    if ground is None:
        return heights(x[..., list(contact_joints(skel)), :], skel).min(axis=(1, 2))
    g = np.asarray(ground, dtype=np.float64)
    if g.ndim == 0:
        g = np.full(len(x), float(g))
    if g.shape != (len(x),) or not np.isfinite(g).all():
        raise ValueError(f"`ground` must be a finite float or one per clip ({len(x)},); got {ground!r}.")
    return g


def acceleration(motion, *, skeleton: str | Skeleton = "humanact12", fps: float | None = None):
    """Mean joint acceleration magnitude.

    ``|x[t+1] - 2 x[t] + x[t-1]| * fps²`` averaged over interior frames and joints.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Metres, T >= 3.
    skeleton : str or Skeleton, default="humanact12"
        Ignored for a Motion.
    fps : float, optional
        Frames per second; default the Motion's, else the skeleton's (20).

    Returns
    -------
    float, or ndarray of shape (B,)
        m/s².
    """
    x, _, rate, single = _prepare(motion, skeleton, fps, min_frames=3)
    acc = np.linalg.norm(np.diff(x, 2, axis=1), axis=-1) * rate**2
    return _out(acc.mean(axis=(1, 2)), single)


def jerk(motion, *, skeleton: str | Skeleton = "humanact12", fps: float | None = None):
    """Mean joint jerk magnitude: third finite difference times fps³, averaged (T >= 4).

    Returns
    -------
    float, or ndarray of shape (B,)
        m/s³.
    """
    x, _, rate, single = _prepare(motion, skeleton, fps, min_frames=4)
    j = np.linalg.norm(np.diff(x, 3, axis=1), axis=-1) * rate**3
    return _out(j.mean(axis=(1, 2)), single)


def acceleration_error(pred, target, *, skeleton: str | Skeleton = "humanact12", fps: float | None = None):
    """Acceleration error (SmoothNet, MEVA): mean ``|acc_pred - acc_target|`` over frames and joints.

    Parameters
    ----------
    pred, target : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Same shape, metres, T >= 3.
    fps : float, optional
        Default ``pred``'s (Motion) or the skeleton's.

    Returns
    -------
    float, or ndarray of shape (B,)
        m/s².
    """
    a, _, rate, single = _prepare(pred, skeleton, fps, min_frames=3)
    b, _, _, _ = _prepare(target, skeleton, rate, min_frames=3)
    if a.shape != b.shape:
        raise ValueError(f"`pred` and `target` must share a shape; got {a.shape[1:]} and {b.shape[1:]}.")
    err = np.linalg.norm(np.diff(a, 2, axis=1) - np.diff(b, 2, axis=1), axis=-1) * rate**2
    return _out(err.mean(axis=(1, 2)), single)


def _foot_contact(x, skel, feet, ground, height_threshold):
    """Foot indices, per-pair contact (B, F, T-1) and horizontal foot speed per frame (B, F, T-1), m/frame."""
    feet = list(foot_joints(skel) if feet is None else feet)
    if not feet or any(not 0 <= f < skel.n_joints for f in feet):
        raise ValueError(f"`feet` must be joint indices in 0..{skel.n_joints - 1}; got {feet!r}.")
    g = _ground(x, skel, ground)
    h = heights(x[:, :, feet], skel) - g[:, None, None]  # (B, T, F)
    low = h < height_threshold
    contact = (low[:, 1:] & low[:, :-1]).transpose(0, 2, 1)
    step = np.linalg.norm(_horizontal(np.diff(x[:, :, feet], axis=1), skel), axis=-1).transpose(0, 2, 1)
    return contact, step


def foot_skating_ratio(
    motion,
    *,
    skeleton: str | Skeleton = "humanact12",
    fps: float | None = None,
    height_threshold: float = 0.05,
    speed_threshold: float = 0.5,
    window: int = 5,
    feet: Sequence[int] | None = None,
    ground=None,
):
    """Foot-skating ratio (GMD): the fraction of frame pairs in which a foot on the ground slides.

    For each pair of adjacent frames and each foot: the foot is *in contact* when its height above the
    ground is below ``height_threshold`` in both frames; it *skates* when, in contact, its horizontal
    speed exceeds ``speed_threshold`` both in that pair and averaged over ``window`` pairs (centred,
    zero-padded at the ends as GMD). A pair counts when either foot skates; the ratio divides by T - 1.
    GMD's numbers: 5 cm, 0.5 m/s (2.5 cm per frame at 20 fps), 5 frames; real HumanML3D clips score
    about 0.05, not 0.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Metres.
    skeleton : str or Skeleton, default="humanact12"
    fps : float, optional
    height_threshold : float, default=0.05
        Metres above the ground.
    speed_threshold : float, default=0.5
        m/s.
    window : int, default=5
        Frames of the speed average.
    feet : sequence of int, optional
        Foot joints; default :func:`foot_joints`.
    ground : float or array of shape (B,), optional
        Ground height along the up axis; default :func:`ground_height` of each clip.

    Returns
    -------
    float, or ndarray of shape (B,)
        In [0, 1].
    """
    if not isinstance(window, (int, np.integer)) or window < 1:
        raise ValueError(f"`window` must be a positive int; got {window!r}.")
    x, skel, rate, single = _prepare(motion, skeleton, fps)
    contact, step = _foot_contact(x, skel, feet, ground, height_threshold)
    speed = step * rate
    mean_speed = uniform_filter1d(speed, size=int(window), axis=-1, mode="constant")
    skating = contact & (speed > speed_threshold) & (mean_speed > speed_threshold)
    return _out(skating.any(axis=1).mean(axis=-1), single)


def foot_skate_distance(
    motion,
    *,
    skeleton: str | Skeleton = "humanact12",
    height_threshold: float = 0.05,
    feet: Sequence[int] | None = None,
    ground=None,
):
    """PhysDiff's *Skate*: mean horizontal displacement of a foot between two frames it touches the ground in.

    Averaged over every (foot, adjacent-frame pair) in contact (both heights below
    ``height_threshold``); 0 when no foot is ever in contact.

    Returns
    -------
    float, or ndarray of shape (B,)
        Metres per frame.
    """
    x, skel, _, single = _prepare(motion, skeleton, None)
    contact, step = _foot_contact(x, skel, feet, ground, height_threshold)
    total = (step * contact).sum(axis=(1, 2))
    count = contact.sum(axis=(1, 2))
    return _out(np.divide(total, count, out=np.zeros_like(total), where=count > 0), single)


def penetration(motion, *, skeleton: str | Skeleton = "humanact12", ground=None):
    """Ground penetration (PhysDiff's *Penetrate*, on joints): how far the lowest joint is below the ground.

    Per frame ``max(0, ground - min_j height)``, averaged over frames.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
    ground : float or array of shape (B,), optional
        Ground height along the up axis. Default :func:`ground_height` of the clip itself, which makes
        the feet's penetration 0 by construction: pass the source clip's ground to judge an edit.

    Returns
    -------
    float, or ndarray of shape (B,)
        Metres.
    """
    x, skel, _, single = _prepare(motion, skeleton, None, min_frames=1)
    g = _ground(x, skel, ground)
    low = heights(x, skel).min(-1)  # (B, T)
    return _out(np.maximum(g[:, None] - low, 0.0).mean(-1), single)


def floating(motion, *, skeleton: str | Skeleton = "humanact12", ground=None, tolerance: float = 0.005):
    """Floating (PhysDiff's *Float*, on joints): how far the lowest joint is above the ground.

    Per frame ``max(0, min_j height - ground - tolerance)``, averaged over frames. Jumps count, as in
    PhysDiff.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
    ground : float or array of shape (B,), optional
        As for :func:`penetration`.
    tolerance : float, default=0.005
        Metres (PhysDiff: 5 mm).

    Returns
    -------
    float, or ndarray of shape (B,)
        Metres.
    """
    x, skel, _, single = _prepare(motion, skeleton, None, min_frames=1)
    g = _ground(x, skel, ground)
    low = heights(x, skel).min(-1)
    return _out(np.maximum(low - g[:, None] - tolerance, 0.0).mean(-1), single)


def bone_length_variation(motion, *, skeleton: str | Skeleton = "humanact12", per_bone: bool = False):
    """Bone-length variation: per bone, the standard deviation of its length over time over its mean.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
    per_bone : bool, default=False
        Return every bone's value instead of the mean over bones.

    Returns
    -------
    float or ndarray of shape (B,), or with ``per_bone`` ndarray of shape (J-1,) or (B, J-1)
        Dimensionless (0 for a rigid skeleton; 0.05 = lengths vary by 5 %). Bones of zero mean length
        give NaN.
    """
    x, skel, _, single = _prepare(motion, skeleton, None, min_frames=1)
    lengths = skel.bone_lengths(x)  # (B, T, J-1)
    mean = lengths.mean(1)
    cv = np.divide(lengths.std(1), mean, out=np.full_like(mean, np.nan), where=mean > 1e-9)
    if per_bone:
        return cv[0] if single else cv
    return _out(cv.mean(-1), single)


class VelocityJump(NamedTuple):
    """Velocity discontinuity at the boundaries of edited frames (see :func:`boundary_velocity_jump`).

    Attributes
    ----------
    jump : float
        Largest velocity change at a boundary, m/s.
    reference : float
        The clip's own velocity changes away from the boundaries (their ``quantile``), m/s.
    ratio : float
        ``jump / reference``; above 1 means the splice is rougher than that share of the clip.
    """

    jump: float
    reference: float
    ratio: float


def boundary_velocity_jump(
    motion,
    mask,
    *,
    skeleton: str | Skeleton = "humanact12",
    fps: float | None = None,
    quantile: float = 0.95,
) -> VelocityJump:
    """Velocity jump where edited frames meet unedited ones, against the clip's own velocity changes.

    The velocity change at frame ``t`` is ``s(t) = max_j |x[t+1,j] - 2 x[t,j] + x[t-1,j]| * fps``: how
    much the fastest-changing joint's velocity (m/s) changes across that frame. A boundary lies
    between frames ``b`` and ``b+1`` where ``mask[b] != mask[b+1]``; a splice there shows up in
    ``s(b)`` and ``s(b+1)``. ``jump`` is the largest ``s`` at any boundary frame, ``reference`` the
    ``quantile`` of ``s`` over all other interior frames.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3)
        One clip, metres, T >= 3.
    mask : array-like of bool, shape (T,)
        True at frames that were changed (e.g. by a refiner or a corruption).
    skeleton : str or Skeleton, default="humanact12"
    fps : float, optional
    quantile : float in [0, 1], default=0.95

    Returns
    -------
    VelocityJump
        All NaN when the mask has no boundary; ``reference`` (and ``ratio``) NaN when every interior
        frame touches a boundary. ``ratio`` is inf for a jump in an otherwise unaccelerated clip.
    """
    x, _, rate, single = _prepare(motion, skeleton, fps, min_frames=3)
    if not single:
        raise ValueError(f"`motion` must be one clip (T, J, 3); got a batch of {len(x)}.")
    if not 0.0 <= quantile <= 1.0:
        raise ValueError(f"`quantile` must be in [0, 1]; got {quantile!r}.")
    n_frames = x.shape[1]
    m = np.asarray(mask)
    if m.shape != (n_frames,) or m.dtype != bool:
        raise ValueError(f"`mask` must be a boolean array of shape ({n_frames},); got {m.dtype} {m.shape}.")
    s = np.zeros(n_frames)
    s[1:-1] = np.linalg.norm(np.diff(x[0], 2, axis=0), axis=-1).max(-1) * rate
    boundaries = np.flatnonzero(m[1:] != m[:-1])
    if boundaries.size == 0:
        return VelocityJump(float("nan"), float("nan"), float("nan"))
    near = np.zeros(n_frames, dtype=bool)
    near[boundaries] = near[boundaries + 1] = True
    near[[0, -1]] = False
    interior = np.zeros(n_frames, dtype=bool)
    interior[1:-1] = True
    jump = float(s[near].max()) if near.any() else 0.0
    others = s[interior & ~near]
    if others.size == 0:
        return VelocityJump(jump, float("nan"), float("nan"))
    reference = float(np.quantile(others, quantile))
    ratio = jump / reference if reference > 0 else (float("inf") if jump > 0 else 0.0)
    return VelocityJump(jump, reference, float(ratio))
