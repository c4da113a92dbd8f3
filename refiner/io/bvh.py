"""BVH (Biovision Hierarchy) export and import of joint-position motions.

A :class:`~refiner.core.motion.Motion` holds joint *positions*; BVH stores fixed bone offsets and
per-frame joint *rotations*. :func:`save_bvh` therefore

1. turns the skeleton's frame into the BVH convention (Y up, subject facing +Z, right-handed;
   for HumanAct12 / UESTC, y-down and facing -z, that is a half turn about x), units stay metres;
2. takes the rest offsets from the first frame's bone vectors, scaled to each bone's mean length
   over the clip (so the rest pose is the first frame and its rotations are all zero);
3. solves each joint's rotation so that forward kinematics hits its children: the minimal (swing)
   rotation for a joint with one child, the best-fit (Kabsch) rotation of all child offsets for a
   joint with several (the SMPL pelvis and spine3); a leaf joint keeps its parent's rotation.

This is exact when every bone keeps its length and the children of a branching joint move as one
rigid body, which holds for real HumanAct12 clips (reloaded positions agree to about 1e-5 m).
Motions whose bone lengths drift, as many generated ones do, cannot be stored exactly with fixed
offsets (Action2Motion's xyz-VAE samples: 86 mm median error): :func:`save_bvh` returns the
round-trip error and warns when it exceeds ``tol``; ``translations=True`` adds per-joint position
channels holding each bone vector, which makes any motion exact.

No comment syntax is part of BVH, so the skeleton is not written as a note: the joint names are the
skeleton's own, and :func:`load_bvh` identifies a registered skeleton by them, reorders the joints
to its order and turns them back into its frame.

Writing is :mod:`refiner.io.bvh_export`, reading :mod:`refiner.io.bvh_import`; their public functions are
importable from here.
"""
from __future__ import annotations

from refiner.io.bvh_export import save_bvh
from refiner.io.bvh_import import bvh_frame, load_bvh, load_bvh_motion

__all__ = ["save_bvh", "load_bvh", "load_bvh_motion", "bvh_frame"]
