"""Import path of 0.1 for the adapters' shared pieces, kept until 0.3: each name warns and comes from its new home.

``refiner.adapters.base`` was split: :class:`AdapterInfo` is part of the plugin contract
(``refiner.plugins``), rotations are core maths (``refiner.core.rotations``), Action2Motion's Lie
tables and kinematics are ``refiner.adapters.lie_kinematics`` and the input helpers
``refiner.adapters.conversion``.
"""
from __future__ import annotations

import importlib
import warnings

__all__: list[str] = []

#: Old name -> the module that holds it now.
MOVED = {
    "AdapterInfo": "refiner.plugins.adapter_info",
    **dict.fromkeys(("call_with_options", "check_raw", "recenter", "resolve_path"), "refiner.adapters.conversion"),
    **dict.fromkeys(("LIE_KINEMATICS", "LieKinematics", "get_lie_kinematics", "lie_forward_kinematics",
                     "lie_inverse_kinematics", "reference_bone_lengths"), "refiner.adapters.lie_kinematics"),
    **dict.fromkeys(("rot6d_to_rotmat", "rotation_between", "rotmat_to_rot6d", "rotmat_to_rotvec", "rotvec_to_rotmat",
                     "yup_to_ydown"), "refiner.core.rotations"),
}


def __getattr__(name: str):
    if name not in MOVED:
        raise AttributeError(f"module 'refiner.adapters.base' has no attribute {name!r}")
    warnings.warn(f"refiner.adapters.base.{name} moved to {MOVED[name]}.{name}; the old path goes in 0.3.",
                  DeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(MOVED[name]), name)
