"""Restricted unpickling of data files (SMPL models, ACTOR's and MDM's pickles): arrays only, no code.

``pickle.load`` calls whatever callable a file names, so a crafted ``.pkl`` runs code before any check of
its content. :func:`load_pickle` resolves only a fixed list of names (numpy arrays, dtypes and scalars;
optionally scipy sparse matrices and a stand-in for chumpy arrays) and refuses every other name before
anything is called; :func:`load_npy` reads an ``.npy`` whose object array (``np.save`` of a dict or list)
goes through it.
"""
from __future__ import annotations

import pickle
from contextlib import nullcontext
from pathlib import Path

import numpy as np

__all__ = ["ChumpyArray", "load_npy", "load_pickle"]

# (module, name) pairs numpy's own pickles use, old and new module paths; all of them only build arrays.
_NUMPY_NAMES = frozenset(
    (module, name)
    for module in ("numpy.core.multiarray", "numpy._core.multiarray")
    for name in ("_reconstruct", "scalar")
) | {("numpy", "ndarray"), ("numpy", "dtype"), ("_codecs", "encode"), ("codecs", "encode")}
# Containers protocol 0-2 pickles build by calling them (chumpy's state holds sets); ``object`` as the
# base of ``copyreg._reconstructor``.
_BUILTIN_NAMES = {"set": set, "frozenset": frozenset, "object": object}
_SPARSE_NAMES = frozenset({"csc_matrix", "csr_matrix", "coo_matrix", "lil_matrix", "dok_matrix", "bsr_matrix"})


class ChumpyArray:
    """Stand-in for a pickled chumpy array (``chumpy.ch.Ch``): keeps the state, never imports chumpy.

    Original SMPL files store ``v_template``, ``shapedirs``, ``posedirs`` and ``weights`` as chumpy
    objects whose pickled state holds the values under ``"x"``.
    """

    def __setstate__(self, state):
        self.state = state

    def to_numpy(self, key: str, path: str) -> np.ndarray:
        """The array this chumpy object holds; ``ValueError`` when its state has none."""
        x = self.state.get("x") if isinstance(self.state, dict) else None
        if not isinstance(x, np.ndarray):
            raise ValueError(
                f"{path!r}: entry {key!r} is a chumpy expression without stored values; re-save the file with "
                f"plain numpy arrays."
            )
        return x


def load_pickle(path, *, what: str, sparse: bool = False, chumpy: bool = False):
    """Unpickle ``path`` allowing only numpy arrays (plus sparse matrices / chumpy stand-ins when asked).

    Parameters
    ----------
    path : path-like or binary file object
        The ``.pkl`` file, or an open stream positioned at a pickle (e.g. inside an ``.npy`` member).
    what : str
        What the file should be, for the error messages (e.g. ``"an SMPL model file"``).
    sparse : bool, default=False
        Allow scipy sparse matrices (SMPL's ``J_regressor``), resolved in ``scipy.sparse`` by name.
    chumpy : bool, default=False
        Map every ``chumpy.*`` class to :class:`ChumpyArray`; top-level dict values of that kind are
        replaced by their arrays.

    Returns
    -------
    object
        What the file holds, built only from the allowed types.

    Raises
    ------
    ValueError
        The file names anything else (nothing it names is called), is truncated or is not a pickle.
    """
    stream = path if hasattr(path, "read") else None
    path = Path(getattr(path, "name", "<stream>")) if stream is not None else Path(path)
    try:
        with open(path, "rb") if stream is None else nullcontext(stream) as f:
            data = _RestrictedUnpickler(f, sparse=sparse, chumpy=chumpy, encoding="latin1").load()
    except _Refused as e:
        raise ValueError(f"{str(path)!r} is not {what}: it names {e}, and only arrays are loaded from it.") from e
    except Exception as e:  # noqa: BLE001 -- a malformed pickle raises anything from EOFError to TypeError
        raise ValueError(f"{str(path)!r} is not {what}: {type(e).__name__}: {e}") from e
    if chumpy and isinstance(data, dict):
        data = {k: v.to_numpy(k, str(path)) if isinstance(v, ChumpyArray) else v for k, v in data.items()}
    return data


def load_npy(path, *, what: str):
    """An ``.npy`` file or stream as ``np.load`` reads it, an object array through :func:`load_pickle`.

    Parameters
    ----------
    path : path-like or seekable binary file object
        The ``.npy`` file (or a member of an ``.npz`` opened as a stream).
    what : str
        What the file should be, for the error messages (e.g. ``"MDM's results.npy"``).

    Returns
    -------
    ndarray
        The array; an object array (``np.save`` of a dict gives a 0-d one: ``.item()`` is the dict) holds
        only what :func:`load_pickle` allows.

    Raises
    ------
    ValueError
        Not an ``.npy`` file, truncated, or a pickle naming anything but arrays (nothing it names is called).
    """
    stream = path if hasattr(path, "read") else None
    name = str(getattr(path, "name", "<stream>") if stream is not None else path)
    with open(path, "rb") if stream is None else nullcontext(stream) as f:
        try:
            version = np.lib.format.read_magic(f)
            header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, _, dtype = header(f)
            if not dtype.hasobject:
                f.seek(0)  # plain arrays: numpy's own reader, pickles refused
                return np.lib.format.read_array(f, allow_pickle=False)
        except Exception as e:  # noqa: BLE001 -- numpy raises several types for a bad header
            raise ValueError(f"{name!r} is not {what}: not a readable .npy file ({type(e).__name__}: {e}).") from e
        arr = load_pickle(f, what=what)
    return np.asarray(arr, dtype=object).reshape(shape) if np.ndim(arr) else np.asarray(arr, dtype=object)


class _Refused(pickle.UnpicklingError):
    """A name outside the allowed list."""


def _reconstructor(cls, base, state):
    """``copyreg._reconstructor`` limited to allowed classes built on ``object`` (protocol 0/1 pickles)."""
    if base is not object:
        raise _Refused(f"copyreg._reconstructor with base {base!r}")
    return object.__new__(cls)


class _RestrictedUnpickler(pickle.Unpickler):
    """Resolves the allowed names only; everything else raises before it is called."""

    def __init__(self, file, *, sparse: bool, chumpy: bool, **kwargs):
        super().__init__(file, **kwargs)
        self._sparse, self._chumpy = sparse, chumpy

    def find_class(self, module, name):
        if (module, name) in _NUMPY_NAMES:
            return super().find_class(module, name)
        if (module, name) in (("copy_reg", "_reconstructor"), ("copyreg", "_reconstructor")):
            return _reconstructor
        if module in ("__builtin__", "builtins") and name in _BUILTIN_NAMES:
            return _BUILTIN_NAMES[name]
        if self._sparse and module.split(".")[:2] == ["scipy", "sparse"] and name in _SPARSE_NAMES:
            import scipy.sparse

            return getattr(scipy.sparse, name)
        if self._chumpy and module.split(".")[0] == "chumpy":
            return ChumpyArray
        raise _Refused(f"{module}.{name}")
