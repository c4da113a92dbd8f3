"""Reading BVH files: the parser, forward kinematics, and matching the joint names to a registered skeleton.

The frame convention (:func:`bvh_frame`) and the layout :func:`~refiner.io.bvh_export.save_bvh` writes are
described in :mod:`refiner.io.bvh`.
"""
from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton, list_skeletons

__all__ = ["bvh_frame", "load_bvh", "load_bvh_motion", "ParsedBvh", "parse_bvh", "read_bvh_file"]


def bvh_frame(skeleton: str | Skeleton) -> np.ndarray:
    """Rotation from a skeleton's frame to the BVH frame (Y up, facing +Z).

    Parameters
    ----------
    skeleton : str or Skeleton

    Returns
    -------
    ndarray of shape (3, 3), float64
        Proper rotation ``C`` with ``p_bvh = C @ p``; its rows are the skeleton-frame directions
        of the BVH X, Y and Z axes (``X = up x forward``).

    Raises
    ------
    ValueError
        If the skeleton's up and forward axes are not perpendicular.
    """
    skel = get_skeleton(skeleton)
    up, fwd = skel.up_vector, skel.forward_vector
    if abs(float(up @ fwd)) > 1e-9:
        raise ValueError(
            f"skeleton {skel.name!r}: `up` ({skel.up}) and `forward` ({skel.forward}) must be different axes."
        )
    return np.stack([np.cross(up, fwd), up, fwd])


def load_bvh(path: str | os.PathLike, *, skeleton: str | Skeleton | None = "auto") -> tuple[np.ndarray, list[str]]:
    """Read joint positions from a BVH file by forward kinematics.

    Parameters
    ----------
    path : str or path-like
    skeleton : str, Skeleton, "auto" or None, default="auto"
        ``"auto"``: if the file's joint names are exactly those of one registered skeleton (as
        :func:`save_bvh` writes them), return the joints in that skeleton's order and frame;
        otherwise in the file's order and frame. A name: require that skeleton. ``None``: always
        the file's order and its BVH frame.

    Returns
    -------
    joints : ndarray of shape (T, J, 3), float32
        Joint positions in the file's units (metres for files from :func:`save_bvh`). ``End Site``
        points are not joints and are left out.
    names : list of str, length J

    Raises
    ------
    ValueError
        Missing file, malformed BVH (naming the problem), or joint names not matching a
        requested skeleton.

    Notes
    -----
    Position channels give a joint's translation from its parent and replace its ``OFFSET``
    (the usual convention for the root); rotation channels compose in the order listed.
    """
    parsed = read_bvh_file(path)
    skel = _match_skeleton(parsed.names, skeleton, path)
    pos = parsed.positions()
    if skel is None:
        return pos.astype(np.float32), list(parsed.names)
    idx = [parsed.names.index(n) for n in skel.joint_names]
    pos = pos[:, idx] @ bvh_frame(skel)  # back from the BVH frame: C is orthogonal
    return pos.astype(np.float32), list(skel.joint_names)


def load_bvh_motion(path: str | os.PathLike, *, skeleton: str | Skeleton = "auto") -> Motion:
    """Read a BVH file written by :func:`save_bvh` (or with a registered skeleton's joints) as a Motion.

    Parameters
    ----------
    path : str or path-like
    skeleton : str, Skeleton or "auto", default="auto"
        As in :func:`load_bvh`, but the joint names must match a registered skeleton.

    Returns
    -------
    Motion
        Joints in the skeleton's frame; ``fps`` from ``Frame Time`` (rounded to 1e-3).

    Raises
    ------
    ValueError
        As :func:`load_bvh`, or when no registered skeleton matches the joint names.
    """
    parsed = read_bvh_file(path)
    skel = _match_skeleton(parsed.names, skeleton, path)
    if skel is None:
        raise ValueError(
            f"{path}: joint names match no registered skeleton ({', '.join(list_skeletons())}); "
            "pass `skeleton=` or use load_bvh for raw joints."
        )
    joints, _ = load_bvh(path, skeleton=skel)
    return Motion(joints, skeleton=skel.name, fps=round(1.0 / parsed.frame_time, 3))


@dataclass
class ParsedBvh:
    """A parsed BVH file: named joints (end sites dropped) in file order and their channel data."""

    names: list[str]
    parents: list[int]
    offsets: np.ndarray  # (J, 3)
    channels: list[list[str]]
    columns: list[int]  # first data column of each joint
    data: np.ndarray  # (T, C)
    frame_time: float

    def positions(self) -> np.ndarray:
        """``(T, J, 3)`` float64 world positions by forward kinematics."""
        n_frames = self.data.shape[0]
        pos = np.zeros((n_frames, len(self.names), 3))
        glob = np.zeros((n_frames, len(self.names), 3, 3))
        for j, chans in enumerate(self.channels):
            trans = np.broadcast_to(self.offsets[j], (n_frames, 3)).copy()
            rot = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
            rot_axes, rot_cols = "", []
            for k, ch in enumerate(chans):
                col = self.data[:, self.columns[j] + k]
                axis = "xyz".index(ch[0])
                if ch.endswith("position"):
                    trans[:, axis] = col
                else:
                    rot_axes += "XYZ"[axis]
                    rot_cols.append(col)
            if rot_axes:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    rot = Rotation.from_euler(rot_axes, np.stack(rot_cols, -1), degrees=True).as_matrix()
            p = self.parents[j]
            if p < 0:
                pos[:, j] = trans
                glob[:, j] = rot
            else:
                pos[:, j] = pos[:, p] + np.einsum("tij,tj->ti", glob[:, p], trans)
                glob[:, j] = glob[:, p] @ rot
        return pos


_CHANNEL_NAMES = {f"{a}{k}" for a in "xyz" for k in ("position", "rotation")}


def read_bvh_file(path: str | os.PathLike) -> ParsedBvh:
    """Parse the BVH file at ``path``; a missing or non-text file is a ValueError."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"BVH file not found: {path}.")
    try:
        text = path.read_text()
    except UnicodeDecodeError as e:
        raise ValueError(f"{path} is not a text BVH file: {e}") from e
    return parse_bvh(text, source=str(path))


def parse_bvh(text: str, *, source: str) -> ParsedBvh:
    """Parse BVH text; every format problem is a ValueError naming ``source``."""

    def fail(msg: str) -> ValueError:
        return ValueError(f"{source}: malformed BVH: {msg}.")

    parts = re.split(r"^[ \t]*MOTION[ \t]*\r?$", text, maxsplit=1, flags=re.MULTILINE | re.IGNORECASE)
    if len(parts) != 2:
        raise fail("no MOTION section")
    head, body = parts
    tokens = head.split()
    if not tokens or tokens[0].upper() != "HIERARCHY":
        raise fail("it must start with HIERARCHY")
    names, parents, offsets, channels, columns = [], [], [], [], []
    stack: list[int] = []  # open blocks: joint index, or -2 for an End Site
    n_cols = 0
    i = 1

    def take_floats(n: int) -> list[float]:
        nonlocal i
        try:
            vals = [float(t) for t in tokens[i : i + n]]
        except ValueError:
            raise fail(f"expected {n} numbers after token {i}; got {tokens[i:i + n]}") from None
        if len(vals) != n:
            raise fail("the hierarchy ends early")
        i += n
        return vals

    while i < len(tokens):
        tok = tokens[i]
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            if i + 2 >= len(tokens) or tokens[i + 2] != "{":
                raise fail(f"{tok} must be followed by a name and '{{'")
            if (key == "ROOT") != (not stack):
                raise fail(f"{tok} {tokens[i + 1]} is in the wrong place")
            if stack and stack[-1] < 0:
                raise fail("an End Site cannot have children")
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            columns.append(n_cols)
            stack.append(len(names) - 1)
            i += 3
        elif key == "END":
            if i + 2 >= len(tokens) or tokens[i + 1].upper() != "SITE" or tokens[i + 2] != "{":
                raise fail("expected 'End Site {'")
            stack.append(-2)
            i += 3
        elif key == "OFFSET":
            i += 1
            vals = take_floats(3)
            if not stack:
                raise fail("OFFSET outside a joint")
            if stack[-1] >= 0:
                offsets[stack[-1]] = vals
        elif key == "CHANNELS":
            if not stack or stack[-1] < 0:
                raise fail("CHANNELS outside a joint")
            try:
                n = int(tokens[i + 1])
            except (IndexError, ValueError):
                raise fail("CHANNELS must be followed by a count") from None
            chans = [t.lower() for t in tokens[i + 2 : i + 2 + n]]
            if len(chans) != n or any(c not in _CHANNEL_NAMES for c in chans):
                raise fail(f"bad channel list for joint {names[stack[-1]]!r}: {tokens[i + 2:i + 2 + n]}")
            channels[stack[-1]] = chans
            n_cols += n
            i += 2 + n
        elif tok == "}":
            if not stack:
                raise fail("unbalanced '}'")
            stack.pop()
            i += 1
        else:
            raise fail(f"unexpected token {tok!r}")
    if stack:
        raise fail("unclosed '{'")
    if not names:
        raise fail("no joints")
    if len(set(names)) != len(names):
        raise fail("joint names must be unique")

    lines = body.strip().split("\n", 2)
    if len(lines) < 2:
        raise fail("the MOTION section needs 'Frames:' and 'Frame Time:' lines")
    f_tok, t_tok = lines[0].split(), lines[1].split()
    try:
        if f_tok[0].lower() != "frames:" or [t.lower() for t in t_tok[:2]] != ["frame", "time:"]:
            raise ValueError
        n_frames, frame_time = int(f_tok[1]), float(t_tok[2])
    except (IndexError, ValueError):
        raise fail(f"the MOTION section must start with 'Frames: N' and 'Frame Time: dt'; got {lines[:2]}") from None
    if n_frames < 1 or not (np.isfinite(frame_time) and frame_time > 0):
        raise fail(f"need Frames >= 1 and Frame Time > 0; got {n_frames} and {frame_time}")
    try:
        values = np.array(lines[2].split() if len(lines) > 2 else [], dtype=np.float64)
    except ValueError:
        raise fail("the frame data must be numbers") from None
    if values.size != n_frames * n_cols:
        raise fail(f"expected {n_frames} frames x {n_cols} channels = {n_frames * n_cols} values; got {values.size}")
    if not np.isfinite(values).all():
        raise fail("the frame data contain NaN or Inf")
    return ParsedBvh(
        names=names,
        parents=parents,
        offsets=np.array(offsets, dtype=np.float64),
        channels=channels,
        columns=columns,
        data=values.reshape(n_frames, n_cols),
        frame_time=frame_time,
    )


def _match_skeleton(names: list[str], skeleton, path) -> Skeleton | None:
    """The skeleton whose joint names are exactly ``names`` (any order), per :func:`load_bvh`'s rule."""
    if skeleton is None:
        return None
    if isinstance(skeleton, str) and skeleton == "auto":
        found = [s for s in map(get_skeleton, list_skeletons()) if sorted(s.joint_names) == sorted(names)]
        if len(found) > 1:
            raise ValueError(
                f"{path}: joint names match several skeletons ({', '.join(s.name for s in found)}); pass `skeleton=`."
            )
        return found[0] if found else None
    skel = get_skeleton(skeleton)
    if sorted(skel.joint_names) != sorted(names):
        missing = sorted(set(skel.joint_names) - set(names))
        extra = sorted(set(names) - set(skel.joint_names))
        raise ValueError(
            f"{path}: joints do not match skeleton {skel.name!r}; missing {missing}, unexpected {extra}."
        )
    return skel
