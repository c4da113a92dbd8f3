"""Skeleton registry: joint names, parents and coordinate conventions of every supported layout;
bone lengths; conversions between layouts live in :mod:`refiner.core.skeleton_conversion` (importable from here).

Tables follow ``generator_formats.md`` section 1 (HumanAct12 / SMPL 24, NTU-VIBE 18 used for UESTC,
HumanML3D 22) and Action2Motion's CMU-Mocap chain (20 joints).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from refiner.core.signal import norms

__all__ = [
    "Skeleton",
    "joint_bone_lengths",
    "with_bone_lengths",
    "get_skeleton",
    "list_skeletons",
    "register_skeleton",
    "bone_lengths",
    "convert",
    "estimated_joints",
]


@dataclass(frozen=True)
class Skeleton:
    """A joint layout and the coordinate convention its data live in.

    Parameters
    ----------
    name : str
        Registry key, e.g. ``"humanact12"``.
    joint_names : tuple of str, length J
    parents : tuple of int, length J
        Parent index of every joint; exactly one root has parent ``-1``. Parents come before
        their children.
    up : str, default="-y"
        Axis pointing up in the data, with sign: ``"-y"`` means y points down (HumanAct12, UESTC).
    forward : str, default="-z"
        Direction the subject faces in the first frame.
    units : str, default="m"
    fps : float, default=20.0
        Native frame rate of the data this skeleton comes with.
    description : str, default=""
    """

    name: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    up: str = "-y"
    forward: str = "-z"
    units: str = "m"
    fps: float = 20.0
    description: str = ""
    _children: tuple[tuple[int, ...], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.joint_names) != len(self.parents):
            raise ValueError(
                f"skeleton {self.name!r}: {len(self.joint_names)} joint names but "
                f"{len(self.parents)} parents."
            )
        roots = [j for j, p in enumerate(self.parents) if p == -1]
        if len(roots) != 1:
            raise ValueError(f"skeleton {self.name!r} must have exactly one root (parent -1); got {roots}.")
        for j, p in enumerate(self.parents):
            if p != -1 and not 0 <= p < j:
                raise ValueError(
                    f"skeleton {self.name!r}: parent of joint {j} must be an earlier joint; got {p}."
                )
        for axis_name, value in (("up", self.up), ("forward", self.forward)):
            if value not in {"+x", "-x", "+y", "-y", "+z", "-z"}:
                raise ValueError(f"skeleton {self.name!r}: `{axis_name}` must be like '+y' or '-z'; got {value!r}.")
        children = [[] for _ in self.parents]
        for j, p in enumerate(self.parents):
            if p >= 0:
                children[p].append(j)
        object.__setattr__(self, "_children", tuple(tuple(c) for c in children))

    @property
    def n_joints(self) -> int:
        return len(self.parents)

    @property
    def root(self) -> int:
        """Index of the root joint (the pelvis in every built-in layout)."""
        return self.parents.index(-1)

    @property
    def bones(self) -> np.ndarray:
        """``(J-1, 2)`` int array of (parent, child) pairs in joint order."""
        return np.array([(p, j) for j, p in enumerate(self.parents) if p >= 0], dtype=np.int64)

    def children(self, joint: int) -> tuple[int, ...]:
        return self._children[joint]

    def index(self, joint_name: str) -> int:
        try:
            return self.joint_names.index(joint_name)
        except ValueError:
            raise ValueError(
                f"skeleton {self.name!r} has no joint {joint_name!r}; joints: {', '.join(self.joint_names)}."
            ) from None

    @property
    def up_vector(self) -> np.ndarray:
        """Unit ``(3,)`` vector pointing up in this skeleton's frame."""
        return _axis_vector(self.up)

    @property
    def forward_vector(self) -> np.ndarray:
        return _axis_vector(self.forward)

    def bone_lengths(self, joints) -> np.ndarray:
        """Bone lengths ``(..., J-1)`` of joints ``(..., J, 3)``, in the joints' units."""
        return bone_lengths(joints, self)


def bone_lengths(joints, skeleton: Skeleton | str) -> np.ndarray:
    """Length of every bone.

    Parameters
    ----------
    joints : array of shape (..., J, 3)
    skeleton : Skeleton or str

    Returns
    -------
    ndarray of shape (..., J-1)
        Distance from each non-root joint to its parent, in joint order.
    """
    skel = get_skeleton(skeleton) if isinstance(skeleton, str) else skeleton
    x = np.asarray(joints)
    bones = skel.bones
    return norms(x[..., bones[:, 1], :] - x[..., bones[:, 0], :])


def joint_bone_lengths(joints, skeleton: Skeleton | str) -> np.ndarray:
    """``(..., J)`` length of the bone ending at each joint (0 at the root), joints ``(..., J, 3)``."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints)
    parents = np.array(skel.parents)
    out = np.linalg.norm(x - x[..., np.maximum(parents, 0), :], axis=-1)
    out[..., parents < 0] = 0.0
    return out


def with_bone_lengths(joints, lengths, skeleton: Skeleton | str) -> np.ndarray:
    """Rebuild joints ``(..., J, 3)`` from the root outwards: each bone keeps its direction and gets
    the length ``lengths[..., j]`` of the bone ending at joint ``j`` (a zero-length bone stays at its parent)."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints)
    out = x.copy()
    for j, p in enumerate(skel.parents):
        if p < 0:
            continue
        v = x[..., j, :] - x[..., p, :]
        norm = np.linalg.norm(v, axis=-1, keepdims=True)
        out[..., j, :] = out[..., p, :] + v / np.maximum(norm, 1e-9) * lengths[..., j : j + 1]
    return out


def _axis_vector(axis: str) -> np.ndarray:
    v = np.zeros(3)
    v["xyz".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
    return v


_SMPL_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar",
    "right_collar", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hand", "right_hand",
)
_SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)

_NTU_VIBE_NAMES = (
    "mid_hip", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder",
    "left_elbow", "left_wrist", "nose", "right_hip", "right_knee", "right_ankle", "left_hip",
    "left_knee", "left_ankle", "left_heel", "right_heel", "head_top",
)
_NTU_VIBE_PARENTS = (-1, 0, 1, 2, 3, 1, 5, 6, 1, 0, 9, 10, 0, 12, 13, 14, 11, 8)

# Action2Motion's CMU chains [0,1,2,3], [0,12,13,14,15], [0,16,17,18,19], [1,4,5,6,7], [1,8,9,10,11];
# sides checked on the data: joints 12-15 and 4-7 sit at +x while the toes point +z (y up).
_CMU_NAMES = (
    "pelvis", "spine", "thorax", "head", "left_shoulder", "left_elbow", "left_wrist", "left_hand",
    "right_shoulder", "right_elbow", "right_wrist", "right_hand", "left_hip", "left_knee",
    "left_ankle", "left_toe", "right_hip", "right_knee", "right_ankle", "right_toe",
)
_CMU_PARENTS = (-1, 0, 1, 2, 1, 4, 5, 6, 1, 8, 9, 10, 0, 12, 13, 14, 0, 16, 17, 18)

_REGISTRY: dict[str, Skeleton] = {}


def register_skeleton(skeleton: Skeleton, *, overwrite: bool = False) -> Skeleton:
    """Add *skeleton* to the registry under ``skeleton.name`` and return it.

    Raises
    ------
    ValueError
        If the name is taken and ``overwrite`` is False.
    """
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"`skeleton` must be a Skeleton; got {type(skeleton).__name__}.")
    if skeleton.name in _REGISTRY and not overwrite:
        raise ValueError(f"skeleton {skeleton.name!r} is already registered; pass overwrite=True to replace it.")
    _REGISTRY[skeleton.name] = skeleton
    return skeleton


def get_skeleton(name: str | Skeleton) -> Skeleton:
    """Look up a registered skeleton by name (a :class:`Skeleton` is returned as is).

    Examples
    --------
    >>> skel = get_skeleton("humanact12")
    >>> skel.n_joints, skel.root, skel.up
    (24, 0, '-y')
    """
    if isinstance(name, Skeleton):
        return name
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown skeleton {name!r}; known: {', '.join(sorted(_REGISTRY))}.") from None


def list_skeletons() -> list[str]:
    """Names of all registered skeletons, sorted."""
    return sorted(_REGISTRY)


register_skeleton(Skeleton(
    "humanact12", _SMPL_NAMES, _SMPL_PARENTS, up="-y", forward="-z",
    description="HumanAct12 / SMPL 24 joints, camera frame: metres, y down, facing -z, left = +x.",
))
register_skeleton(Skeleton(
    "uestc", _NTU_VIBE_NAMES, _NTU_VIBE_PARENTS, up="-y", forward="-z",
    description="UESTC / NTU-VIBE 18 joints (Action2Motion layout), camera frame: y down, facing -z.",
))
register_skeleton(Skeleton(
    "humanml3d", _SMPL_NAMES[:22], _SMPL_PARENTS[:22], up="+y", forward="+z",
    description="HumanML3D 22 joints (SMPL without hands): metres, y up, facing +z, floor at y=0.",
))
register_skeleton(Skeleton(
    "cmu_mocap", _CMU_NAMES, _CMU_PARENTS, up="+y", forward="+z",
    description="Action2Motion's CMU-Mocap subset, 20 joints, y up; loaded in metres.",
))


# the conversions need the registry above; imported last so that their names live here too
from refiner.core.skeleton_conversion import convert, estimated_joints  # noqa: E402
