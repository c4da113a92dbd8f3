"""``motion-refiner doctor``: what is installed and what is found.

:func:`diagnose` collects, as a JSON-serialisable dict: the package, every shipped weights folder
(verified against its manifest), the Action2Motion recognisers (shipped copy or data folder), the
data sources under ``$MOTION_REFINER_DATA`` (found and missing files), torch and CUDA, and the thread
settings. :func:`doctor_run` prints it (or the JSON) and always exits 0: a missing optional file
is information, not an error. Like :mod:`refiner.cli.main`, this module writes to stdout.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import refiner
from refiner.core import manifest as mf
from refiner.evaluation.evaluator_weights import packaged_recognizer
from refiner.io.data_sources import DATA_ENV, data_status
from refiner.io.datasets import default_data_dir

__all__ = ["diagnose", "doctor_arguments", "doctor_run", "format_report"]

_WEIGHTS = Path(__file__).resolve().parents[1] / "weights"


def diagnose() -> dict:
    """Everything ``doctor`` reports (see the module docstring)."""
    return {
        "package": {"version": refiner.__version__, "path": str(Path(refiner.__file__).parent),
                    "python": platform.python_version()},
        "weights": [_weights_folder(p) for p in sorted(_WEIGHTS.iterdir()) if (p / "manifest.json").is_file()],
        "evaluators": _evaluators(),
        "data": {"env": DATA_ENV, "env_value": os.environ.get(DATA_ENV), "folder": str(default_data_dir()),
                 "sources": data_status()},
        "torch": _torch(),
        "threads": _threads(),
    }


def _motion_models(folder: Path, manifest: dict) -> dict:
    """The motion models a ``<skeleton>-motion`` folder lists, each checked against its sha256 (``ValueError``)."""
    paths = {}
    for name, entry in manifest.get("models", {}).items():
        path = folder / entry["file"]
        if not path.is_file() or mf.file_sha256(path) != entry["sha256"]:
            raise ValueError(f"{str(path)!r} is missing or does not match the sha256 in its manifest.")
        paths[name] = path
    return paths


def _weights_folder(folder: Path) -> dict:
    """One shipped weights folder: its kind, what it lists and whether its manifest and files verify."""
    row = {"name": folder.name, "path": str(folder), "kind": "unknown", "entries": [], "verified": False,
           "error": None}
    try:
        listed = json.loads((folder / "manifest.json").read_text())
        if "generators" in listed:
            row["kind"], (_, paths) = "reference generators", mf.read_generator_manifest(folder)
        elif "evaluators" in listed:
            row["kind"], (_, paths) = "evaluators", mf.read_evaluator_manifest(folder)
        elif listed.get("kind") == "motion_model":
            row["kind"], paths = "motion model (default refiner)", _motion_models(folder, listed)
        else:
            from refiner.refinement.pipeline import _PARTS  # imports torch: only for a refiner folder

            row["kind"], (_, paths) = "refiner", mf.read_refiner_manifest(folder, _PARTS)
        row["entries"], row["verified"] = sorted(paths), True
    except (ValueError, OSError) as e:  # a corrupt folder is reported, not raised
        row["error"] = str(e)
    return row


def _evaluators() -> list[dict]:
    """Each Action2Motion recogniser: the shipped copy, the data-folder files, and which one loads."""
    from refiner.evaluation.evaluators import RECOGNIZERS, evaluators_dir  # imports torch: here, so --help stays cheap

    folder = evaluators_dir()
    rows = []
    for name, (_, st_file, tar_file) in RECOGNIZERS.items():
        try:
            shipped, error = packaged_recognizer(name), None
        except ValueError as e:
            shipped, error = None, str(e)
        in_data = [str(folder / f) for f in (st_file, tar_file) if (folder / f).is_file()]
        used = str(shipped) if shipped else (in_data[0] if in_data else None)
        rows.append({"name": name, "shipped": str(shipped) if shipped else None, "data_folder": in_data,
                     "used": used, "error": error, "expected": [str(folder / st_file), str(folder / tar_file)]})
    return rows


def _torch() -> dict:
    import torch  # here, not at the top: --help must not load torch

    cuda = torch.cuda.is_available()
    return {"version": torch.__version__, "cuda_available": cuda, "cuda_build": torch.version.cuda,
            "devices": [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())] if cuda else []}


def _threads() -> dict:
    import torch  # here, not at the top: --help must not load torch

    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"cpu_count": os.cpu_count(), "usable_cpus": affinity, "torch_threads": torch.get_num_threads(),
            "torch_interop_threads": torch.get_num_interop_threads(),
            "env": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}}


def doctor_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print the report as JSON")


def doctor_run(args: argparse.Namespace) -> int:
    report = diagnose()
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    for line in format_report(report):
        print(line)
    return 0


def format_report(report: dict) -> list[str]:
    """The lines ``doctor`` prints for :func:`diagnose`'s report."""
    pkg, t, th, data = report["package"], report["torch"], report["threads"], report["data"]
    lines = [f"motion-refiner {pkg['version']} at {pkg['path']} (Python {pkg['python']}, {sys.platform})", "",
             "weights (shipped, checked against their manifests):"]
    for w in report["weights"]:
        state = "verified" if w["verified"] else f"FAILED: {w['error']}"
        lines.append(f"  {w['name']:<18} {w['kind']:<21} {state}; {', '.join(w['entries'])}")
    lines += ["", "evaluators (Action2Motion recognisers):"]
    for e in report["evaluators"]:
        where = "shipped copy" if e["shipped"] else ("data folder" if e["used"] else "missing")
        lines.append(f"  {e['name']:<16} {where}: {e['used'] or e['error'] or ' or '.join(e['expected'])}")
    env = f"${data['env']}={data['env_value']}" if data["env_value"] else f"${data['env']} not set"
    lines += ["", f"data folder {data['folder']} ({env}):"]
    for s in data["sources"]:
        found = ", ".join(s["found"]) or "none"
        missing = f"; missing {', '.join(s['missing'])}" if s["missing"] else ""
        lines.append(f"  {s['name']:<11} {s['folder']}: found {found}{missing}")
    gpu = f"CUDA available ({', '.join(t['devices'])})" if t["cuda_available"] else "CUDA not available"
    env_threads = ", ".join(f"{k}={v}" for k, v in th["env"].items() if v is not None) or "no thread variables set"
    lines += ["", f"torch {t['version']} (CUDA build {t['cuda_build'] or 'none'}), {gpu}",
              f"threads: {th['usable_cpus']} usable CPUs of {th['cpu_count']}, torch {th['torch_threads']} "
              f"(inter-op {th['torch_interop_threads']}), {env_threads}"]
    return lines
