"""Command-line options several sub-commands share: GIF size, torch threads, ints, action and generator names."""
from __future__ import annotations

import argparse

__all__ = ["GIF_PANEL_PX", "GIF_DPI", "gif_size_argument", "threads_argument", "set_threads", "positive_int",
           "int_or_str", "GENERATOR_NAMES"]

#: Default edge of one GIF panel in pixels (the demo's and ``refine --gif``'s before/after animations).
GIF_PANEL_PX = 320
#: The reference generators' short names (``refiner.reference.GENERATOR_KINDS``' keys, which import torch;
#: a test keeps the two equal), choices of ``demo --generator`` and ``train-generator --kind``.
GENERATOR_NAMES = ("a2m", "actor", "mdm", "a2m-large", "actor-large")
#: Resolution the GIFs are drawn at; a panel is ``GIF_PANEL_PX / GIF_DPI`` inches.
GIF_DPI = 80


def gif_size_argument(p: argparse.ArgumentParser) -> None:
    """``--gif-size PX``: the edge of each GIF panel."""
    p.add_argument("--gif-size", type=positive_int, default=GIF_PANEL_PX, metavar="PX",
                   help=f"edge of each GIF panel in pixels (default {GIF_PANEL_PX}; before/after side by side)")


def positive_int(text: str) -> int:
    """An argparse type: a positive int."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive int; got {text!r}")
    return value


def threads_argument(p: argparse.ArgumentParser) -> None:
    """``--threads N``: torch CPU threads, default 1."""
    # The networks are small: on CPU one thread is several times faster than torch's default
    # (on a busy 2-core machine a GRU step took 20 ms with 2 threads and 0.07 ms with 1).
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1: fastest for these networks)")


def set_threads(threads: int | None) -> None:
    """Set torch's CPU threads (None: leave torch's choice); a non-positive count is a ValueError."""
    if threads is None:
        return
    if threads < 1:
        raise ValueError(f"`--threads` must be a positive int; got {threads}.")
    import torch  # here, not at the top: `motion-refiner --help` must not load torch

    torch.set_num_threads(threads)


def int_or_str(value: str):
    """``"3"`` -> 3, ``"walk"`` -> ``"walk"`` (an action given by index or by name)."""
    value = value.strip()
    return int(value) if value.lstrip("-").isdigit() else value
