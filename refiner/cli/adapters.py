"""``motion-refiner adapters``: list the installed generator adapters (built-in and from entry points)."""
from __future__ import annotations

import argparse

from refiner.plugins.manager import get_plugin_manager

__all__ = ["adapters_arguments", "adapters_run"]


def adapters_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-autoload", action="store_true", help="only the built-in adapters (skip entry points)")


def adapters_run(args: argparse.Namespace) -> int:
    infos = get_plugin_manager(autoload=not args.no_autoload).adapters()
    rows = [("adapter", "skeletons", "fps", "up", "from", "format")]
    rows += [(i.name, ",".join(i.skeletons), f"{i.fps:g}", i.up, i.source, i.format) for i in infos.values()]
    widths = [max(len(r[k]) for r in rows) for k in range(5)]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r[:5], widths)) + "  " + r[5])
    return 0
