"""``motion-refiner refine``: refine motion files (.npy/.npz joints or raw generator output through an adapter).

Each input file gives one output (``.npy``, or ``.npz`` for clips of different lengths; the generator's own
format when its adapter writes one, e.g. MDM's ``results.npy``) and, on request, its report, before/after
GIFs and BVH files. A file that cannot be read or refined is reported and skipped; the others are still written.
"""
from __future__ import annotations

import argparse
import json
import sys
import traceback
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from refiner.cli.options import GIF_DPI, gif_size_argument, int_or_str, set_threads, threads_argument
from refiner.core.motion import Motion
from refiner.core.skeletons import get_skeleton
from refiner.io.bvh import save_bvh
from refiner.plugins.manager import get_plugin_manager

__all__ = ["refine_arguments", "refine_run", "load_input"]


_SUFFIXES = (".npy", ".npz")


def refine_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=Path, metavar="IN",
                   help=".npy/.npz of joints (T, J, 3) or (N, T, J, 3), raw generator output with --adapter, "
                        "or a folder of such files")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="output .npy for a single input, else a folder (<name>.npy per input); in the generator's "
                        "own format when its adapter writes one (mdm: results.npy)")
    p.add_argument("--adapter", default=None, help="convert raw generator output with this adapter "
                                                   "(`motion-refiner adapters` lists them)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="adapter option, repeatable (e.g. representation=lie); VALUE is parsed as JSON when it can be")
    p.add_argument("--skeleton", default="humanact12", help="skeleton of the joints / adapter target")
    p.add_argument("--action", default=None, help="action name or index for every clip (default: inferred)")
    p.add_argument("--method", default=None, choices=["motion", "concepts"],
                   help="motion (the default): the learned motion model; concepts: the paper's method (anchor scores "
                        "and transition residuals); default: motion, concepts with --refiner")
    p.add_argument("--mode", default=None, choices=["full", "anchor", "transition"],
                   help="with --method concepts: which of its steps run (default full)")
    p.add_argument("--fps", type=float, default=20.0, help="frame rate of joint files (default 20)")
    p.add_argument("--refiner", type=Path, default=None,
                   help="folder of a saved concepts refiner (`motion-refiner train`; default: shipped weights)")
    p.add_argument("--concept-snap", type=float, default=0.0, metavar="W",
                   help="with --method concepts: move every anchor W of the way (0-1) onto its action's nearest anchor "
                        "concept; needs --action; realism over fidelity (default 0: off)")
    p.add_argument("--report", action="store_true", help="write <out>.report.json next to each output")
    p.add_argument("--gif", action="store_true", help="write a before/after <out>.gif next to each output")
    gif_size_argument(p)
    p.add_argument("--bvh", action="store_true", help="write the refined motion as <out>.bvh (exact joint positions)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    threads_argument(p)


def refine_run(args: argparse.Namespace) -> int:
    method = args.method or ("concepts" if args.refiner is not None else "motion")
    if method == "motion":  # the options of the concepts method, refused before anything is read
        given = [name for name, on in (("--refiner", args.refiner is not None), ("--mode", args.mode is not None),
                                       ("--concept-snap", bool(args.concept_snap))) if on]
        if given:
            raise ValueError(f"{', '.join(given)} belong{'s' * (len(given) == 1)} to `--method concepts`; the default "
                             "method, motion, has neither modes nor a concept snap.")
    args.mode = args.mode or "full"
    set_threads(args.threads)
    skeleton = get_skeleton(args.skeleton).name
    options = _parse_options(args.option)
    if options and args.adapter is None:
        raise ValueError("`--option` needs `--adapter`.")
    if args.input.is_dir():
        inputs = sorted(p for p in args.input.iterdir() if p.is_file() and p.suffix.lower() in _SUFFIXES)
        if not inputs:
            raise ValueError(f"no .npy or .npz files in {str(args.input)!r}.")
        if args.out.suffix.lower() in _SUFFIXES:
            raise ValueError(f"IN is a folder, so `-o` must be a folder; got the file name {str(args.out)!r}.")
        targets = [args.out / (p.stem + ".npy") for p in inputs]
        clashes = sorted({t.name for t in targets if targets.count(t) > 1})
        if clashes:  # refuse before writing anything: a second file would overwrite the first's result
            names = ", ".join(p.name for p, t in zip(inputs, targets) if t.name in clashes)
            raise ValueError(f"these inputs would all be written to the same output ({', '.join(clashes)}): "
                             f"{names}; rename them or refine them one by one.")
    elif args.input.is_file():
        if args.input.suffix.lower() not in _SUFFIXES:
            raise ValueError(f"IN must be a .npy or .npz file or a folder; got {str(args.input)!r}.")
        inputs = [args.input]
        targets = [args.out if args.out.suffix.lower() == ".npy" else args.out / (args.input.stem + ".npy")]
    else:
        raise ValueError(f"IN {str(args.input)!r} does not exist.")
    if args.concept_snap and args.action is None:  # an inferred action is never snapped to: it would do nothing
        raise ValueError("`--concept-snap` needs `--action`: the anchors are snapped onto that action's concepts.")
    refiner = _load_refiner(method, args.refiner, skeleton, args.concept_snap)
    pm = get_plugin_manager() if args.adapter is not None else None
    if pm is not None:
        pm.get_adapter(args.adapter)  # an unknown adapter is a usage error, not a per-file failure

    failed, done, changed_total, frames_total = [], 0, 0, 0
    single = len(inputs) == 1  # a folder gets a bar over its files; one file says what it is doing
    if single:
        print(f"refining {inputs[0]}" + (" and drawing its GIF" if args.gif else "") + " ...", flush=True)
    bar = tqdm(list(zip(inputs, targets)), desc="refine", unit="file", disable=single)
    for path, target in bar:
        bar.set_postfix_str(path.name)
        try:
            written, changed, frames = _refine_file(path, target, args, refiner, pm, skeleton, options,
                                                    progress=single)
        except (ValueError, TypeError, OSError) as e:
            failed.append(path)
            tqdm.write(f"FAILED {path}: {e}", file=sys.stderr)
            continue
        except Exception as e:  # noqa: BLE001 -- one bad file must not stop the batch; keep the trace
            failed.append(path)
            tqdm.write(f"FAILED {path}: unexpected {type(e).__name__}: {e}\n{traceback.format_exc()}", file=sys.stderr)
            continue
        done += 1
        changed_total, frames_total = changed_total + changed, frames_total + frames
        tqdm.write(f"refined {path} -> {', '.join(str(w) for w in written)} ({changed} of {frames} frames changed)")
    print(f"refined {done} of {len(inputs)} file(s), {changed_total} of {frames_total} frames changed"
          + (f"; {len(failed)} failed: " + ", ".join(p.name for p in failed) if failed else ""))
    return 1 if failed else 0


def _load_refiner(method: str, folder: Path | None, skeleton: str, concept_snap: float):
    """The refiner of ``method``: the shipped one for ``skeleton``, or the concepts refiner saved in ``folder``."""
    # these import torch: here, so that --help stays cheap
    if method == "motion":
        from refiner.refinement.motion_refiner import MotionRefiner

        return MotionRefiner.pretrained(skeleton)
    from refiner.refinement.pipeline import Refiner

    snap = {"concept_snap": concept_snap} if concept_snap else {}
    return Refiner.load(folder, **snap) if folder is not None else Refiner.pretrained(skeleton, **snap)


def load_input(path, *, adapter: str | None = None, skeleton: str = "humanact12", options: dict | None = None,
               fps: float = 20.0, plugin_manager=None) -> tuple[list, bool]:
    """Read one ``.npy``/``.npz`` file as canonical motions.

    Parameters
    ----------
    path : path
        ``.npy`` holding joints ``(T, J, 3)`` / ``(N, T, J, 3)`` (metres, the skeleton's frame) or a
        generator's raw output; ``.npz`` holding one array, or named arrays (``joints``/``motion``/
        ``output`` are looked for; an adapter gets them all as a dict when there are several), plus
        optional per-clip labels under ``action``/``actions``/``labels``. Pickles are refused, except by an
        adapter that reads its generator's own file (``mdm``: ``results.npy``, restricted unpickler).
    adapter : str, optional
        Convert with this adapter (plugin) instead of reading joints.
    skeleton : str, default="humanact12"
    options : dict, optional
        Adapter options.
    fps : float, default=20.0
        Frame rate of joint files.
    plugin_manager : PluginManager, optional

    Returns
    -------
    motions : list of Motion
    batched : bool
        Whether the file held a batch (written back as ``(N, T, J, 3)``).

    Raises
    ------
    ValueError
        Unreadable file, no usable array, wrong shape, or whatever the adapter rejects.
    """
    motions, batched, _ = _load(Path(path), adapter, skeleton, options, fps, plugin_manager)
    return motions, batched


def _load(path: Path, adapter, skeleton, options, fps, plugin_manager) -> tuple[list, bool, object]:
    """:func:`load_input`, plus the raw output as read (for an adapter that writes its own format back)."""
    pm = plugin_manager if plugin_manager is not None or adapter is None else get_plugin_manager()
    raw = pm.read_file(adapter, path) if adapter is not None else None  # the generator's own file format, if read
    labels = None
    if raw is None:
        raw, labels = _read_array_file(path, want_dict=adapter is not None)
    if adapter is not None:
        motions = pm.convert(adapter, raw, skeleton=skeleton, options=options or {})
        batched = True
    else:
        arr = np.asarray(raw)
        if arr.ndim not in (3, 4) or arr.shape[-1] != 3:
            raise ValueError(f"{path.name}: joints must have shape (T, J, 3) or (N, T, J, 3); got {tuple(arr.shape)} "
                             "(raw generator output needs --adapter).")
        batched = arr.ndim == 4
        motions = []
        for i, clip in enumerate(arr if batched else arr[None]):
            try:
                motions.append(Motion(clip, skeleton=skeleton, fps=fps))
            except ValueError as e:  # name the clip of a batch, whatever is wrong with it
                raise ValueError(f"{path.name}: " + (f"clip {i} of {len(arr)}: " if batched else "") + str(e)) from e
    if labels is not None:
        labels = np.atleast_1d(labels)
        if len(labels) not in (1, len(motions)):
            raise ValueError(f"{path.name}: {len(labels)} action labels for {len(motions)} clips.")
        labels = np.broadcast_to(labels, (len(motions),))
        motions = [m if m.action is not None else Motion(m.joints, skeleton=m.skeleton, fps=m.fps, action=int(a))
                   for m, a in zip(motions, labels)]
    return motions, batched, raw


def _refine_file(path: Path, target: Path, args, refiner, pm, skeleton: str, options: dict, *,
                 progress: bool = False):
    """Refine one file and write its outputs (``progress``: a bar while drawing GIFs); returns
    ``(paths written, frames changed, frames)``."""
    if target.resolve() == path.resolve():
        raise ValueError("the output would replace the input; choose another -o.")
    motions, batched, raw = _load(path, args.adapter, skeleton, options, args.fps, pm)
    n = len(motions)
    own_format = pm is not None and bool(pm.owner_hook(args.adapter, "refiner_write_refined").get_hookimpls())
    ragged = len({m.n_frames for m in motions}) > 1 and not own_format
    main_out = target.with_suffix(".npz") if ragged else target
    stem = target.with_suffix("")
    per_clip = [""] if n == 1 else [f"_{i:03d}" for i in range(n)]
    outputs = [main_out]
    if args.report:
        outputs.append(Path(f"{stem}.report.json"))
    if args.gif:
        outputs += [Path(f"{stem}{s}.gif") for s in per_clip]
    if args.bvh:
        outputs += [Path(f"{stem}{s}.bvh") for s in per_clip]
    existing = [str(o) for o in outputs if o.exists()]
    if existing and not args.force:
        raise ValueError(f"refusing to overwrite {', '.join(existing)}; pass --force.")

    action = None if args.action is None else int_or_str(args.action)
    refined, reports = [], []
    for i, motion in enumerate(motions):
        try:
            out, report = refiner.refine(motion, action=action, mode=args.mode, return_report=True)
        except ValueError as e:
            raise ValueError(f"clip {i} of {n}: {e}") from e
        refined.append(out)
        reports.append(report)

    target.parent.mkdir(parents=True, exist_ok=True)
    # e.g. MDM's results.npy: same keys and layout, only the refined frames changed; a writer may decline (None)
    if not own_format or pm.write_refined(args.adapter, main_out, raw, motions, refined) is None:
        main_out = target.with_suffix(".npz") if len({m.n_frames for m in motions}) > 1 else target
        if main_out != target and main_out.exists() and not args.force:
            raise ValueError(f"refusing to overwrite {main_out}; pass --force.")
        if main_out.suffix == ".npz":
            np.savez(main_out, **{f"clip_{i:03d}": m.joints for i, m in enumerate(refined)})
        else:
            stacked = np.stack([m.joints for m in refined])
            np.save(main_out, stacked if batched else stacked[0])
    written = [main_out]
    if args.report:
        payload = {"input": str(path), "output": str(main_out), "adapter": args.adapter, "method": refiner.method,
                   "mode": args.mode, "skeleton": skeleton, "clips": [r.to_dict() for r in reports]}
        Path(f"{stem}.report.json").write_text(json.dumps(payload, indent=1) + "\n")
        written.append(Path(f"{stem}.report.json"))
    if args.gif:
        from refiner.io import viz  # imports matplotlib: here, so that --help stays cheap

        for s, before, after, report in zip(per_clip, motions, refined, reports):
            written += viz.animate_change(before, after, report, path=Path(f"{stem}{s}.gif"),
                                          labels=("input", "refined"), mp4=False, panel_size=args.gif_size / GIF_DPI,
                                          dpi=GIF_DPI, progress=progress)
    if args.bvh:
        for s, after in zip(per_clip, refined):
            save_bvh(after, Path(f"{stem}{s}.bvh"), translations=True)
            written.append(Path(f"{stem}{s}.bvh"))
    changed = sum(int(r.changed_frames.sum()) for r in reports)
    return written, changed, sum(r.n_frames for r in reports)


def _read_array_file(path: Path, *, want_dict: bool):
    """``(array or dict of arrays, labels or None)`` from a .npy / .npz file, without pickles."""
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as e:  # numpy raises several types for corrupt or pickled files
        raise ValueError(f"{path.name} is not a readable .npy/.npz array file: {e}") from e
    if isinstance(data, np.ndarray):
        return data, None
    with data:
        arrays = {k: data[k] for k in data.files}
    labels = next((arrays.pop(k) for k in ("action", "actions", "labels") if k in arrays), None)
    if not arrays:
        raise ValueError(f"{path.name} holds no arrays besides labels.")
    for key in ("joints", "motion", "output"):
        if key in arrays and not want_dict:
            return arrays[key], labels
    if len(arrays) == 1:
        return next(iter(arrays.values())), labels
    if want_dict:
        return arrays, labels
    raise ValueError(f"{path.name} holds several arrays ({', '.join(arrays)}); name the joints 'joints'.")


def _parse_options(items) -> dict:
    options = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"`--option` must be KEY=VALUE; got {item!r}.")
        try:
            options[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            options[key.strip()] = value
    return options
