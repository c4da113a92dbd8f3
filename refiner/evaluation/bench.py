"""``motion-refiner bench``: benchmarks that print figures (speed and quality targets live here).

Every suite is a function ``(data_dir, out_dir, quick) -> str`` returning a Markdown section that
is printed as it is produced and, with ``--out``, collected into ``REPORT.md``; with ``--out`` each
suite also writes its figures as ``<suite>.json`` (:func:`write_record`), the numbers of its tables.
``refiner``/``speed``, ``flaws``, ``samples`` and ``skeletons`` live in :mod:`refiner.evaluation.bench_refiner`,
:mod:`refiner.evaluation.bench_flaws`, :mod:`refiner.evaluation.bench_samples` and :mod:`refiner.evaluation.bench_skeletons`,
imported on first use.
"""
from __future__ import annotations

import importlib
import json
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["SUITES", "run_benchmarks", "markdown_table", "write_record", "one_thread"]

#: suites kept in their own modules (they import this one): function name -> module
_ELSEWHERE = {"bench_refiner": "refiner.evaluation.bench_refiner", "bench_speed": "refiner.evaluation.bench_refiner",
              "bench_flaws": "refiner.evaluation.bench_flaws", "bench_samples": "refiner.evaluation.bench_samples",
              "bench_skeletons": "refiner.evaluation.bench_skeletons"}


def __getattr__(name: str):
    """``refiner.evaluation.bench.bench_refiner`` and the other moved suites, imported on first use."""
    if name in _ELSEWHERE:
        return getattr(importlib.import_module(_ELSEWHERE[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def markdown_table(header: list[str], rows: list[list]) -> str:
    def fmt(v):
        return f"{v:.3f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def write_record(out: Path | None, suite: str, record: dict) -> dict:
    """Write a suite's figures as ``<suite>.json`` in ``out`` (nothing when ``out`` is None); returns ``record``."""
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / f"{suite}.json").write_text(json.dumps(record, indent=1))
    return record


def bench_concepts(data: Path | None, out: Path | None, quick: bool) -> str:
    """Segmentation speed on all HumanAct12 clips, the λ table beside the paper's Table 2, K-means."""
    from sklearn.cluster import KMeans

    from refiner.concepts.anchors import root_relative
    from refiner.concepts.segmentation import DEFAULT_PENALTY, segment
    from refiner.io.datasets import load_humanact12

    dataset = load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")
    if quick:
        dataset = dataset.subset(range(0, len(dataset), 40))
    lines = [f"## Concepts (HumanAct12, {len(dataset)} clips, {dataset.n_frames} frames)", ""]

    t0 = time.perf_counter()
    segs = [segment(m.joints, penalty=DEFAULT_PENALTY) for m in dataset]
    seconds = time.perf_counter() - t0
    lines.append(f"Segmenting all {len(dataset)} clips at λ={DEFAULT_PENALTY:g}: **{seconds:.1f} s** "
                 f"wall on this machine (target: 30 s or less for 1,191 clips).")
    print(lines[-1], flush=True)

    paper = {100: (0.89, "97.7%"), 200: (0.94, "98.6%"), 300: (1.08, "98.3%"), 400: (1.22, "97.1%")}
    rec = {"clips": len(dataset), "frames": dataset.n_frames, "penalty": DEFAULT_PENALTY,
           "segment_seconds": seconds, "penalties": [], "kmeans": []}
    for lam in (100.0, 200.0, 300.0, 400.0):
        seg_l = segs if lam == DEFAULT_PENALTY else [segment(m.joints, penalty=lam) for m in dataset]
        n_trans = np.array([s.n_transitions for s in seg_l])
        durations = np.concatenate([s.durations for s in seg_l])
        err = [np.linalg.norm(s.reconstruct() - m.joints, axis=-1) for s, m in zip(seg_l, dataset)]
        overall = 100 * np.concatenate([e.ravel() for e in err]).mean()
        per_action = [100 * np.concatenate([e.ravel() for e, m in zip(err, dataset) if m.action == a]).mean()
                      for a in np.unique(dataset.actions)]
        r = {"penalty": lam, "transitions_per_clip": float(n_trans.mean()),
             "mean_transition_frames": float(durations.mean()), "mpjpe_cm": float(overall),
             "mpjpe_mean_of_actions_cm": float(np.mean(per_action)), "paper_mpjpe_cm": paper[int(lam)][0]}
        rec["penalties"].append(r)
        print(f"  λ={lam:g}: {r['transitions_per_clip']:.2f} transitions/clip, {r['mean_transition_frames']:.1f} "
              f"frames each, MPJPE {overall:.3f} cm", flush=True)
    rows = [[f"{r['penalty']:g}", r["transitions_per_clip"], r["mean_transition_frames"], r["mpjpe_cm"],
             r["mpjpe_mean_of_actions_cm"], r["paper_mpjpe_cm"]] for r in rec["penalties"]]
    lines += ["", "λ in cm² per joint (see `refiner.concepts.segmentation`). MPJPE of the spline reconstruction, cm.", "",
              markdown_table(["λ", "transitions / clip", "mean transition frames", "MPJPE (all frames)",
                              "MPJPE (mean of actions)", "paper Table 2 MPJPE"], rows)]

    ks = (2, 4, 8, 12, 16)
    for a in np.unique(dataset.actions):
        poses = np.concatenate([root_relative(m.joints[s.anchors]) for s, m in zip(segs, dataset) if m.action == a])
        flat = poses.reshape(len(poses), -1)
        dist = {}
        for k in ks:
            if k > len(flat):
                dist[str(k)] = None
                continue
            km = KMeans(k, n_init=2, random_state=0).fit(flat)
            dist[str(k)] = float(100 * np.linalg.norm(poses - km.cluster_centers_[km.labels_].reshape(poses.shape),
                                                      axis=-1).mean())
        rec["kmeans"].append({"action": dataset.action_names[a], "anchors": len(poses), "distance_cm": dist})
    krows = [[r["action"], r["anchors"]] + ["-" if v is None else v for v in r["distance_cm"].values()]
             for r in rec["kmeans"]]
    lines += ["", "Anchor K-means: mean joint distance to the assigned centre (cm) by number of clusters.", "",
              markdown_table(["action", "anchors"] + [f"k={k}" for k in ks], krows)]
    write_record(out, "concepts", rec)
    return "\n".join(lines)


def _humanact12_and_recognizer(data: Path | None, *, hidden: str):
    """HumanAct12 and the Action2Motion recogniser, from ``data`` (folder holding humanact12/) or the defaults."""
    from refiner.evaluation.evaluators import load_recognizer
    from refiner.io.datasets import load_humanact12

    dataset = load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")
    recognizer = load_recognizer("humanact12", hidden=hidden,
                                 directory=None if data is None else Path(data).parent / "evaluators")
    return dataset, recognizer


def _metrics(summary: dict) -> dict:
    """An evaluation summary as JSON: metric -> ``[mean, 95 % half-width]``."""
    return {k: [float(m), float(h)] for k, (m, h) in summary.items()}


def _pm(value: list, scale: float = 1.0, spec: str = ".3f") -> str:
    """``[mean, half-width]`` as the tables print it, ``mean ± half-width``."""
    return f"{scale * value[0]:{spec}} ± {scale * value[1]:{spec}}"


@contextmanager
def one_thread():
    """Torch and BLAS on one thread, restored after; also a decorator. The networks are small: one
    thread is several times faster on CPU, and on a busy machine two can be 30-100 times slower."""
    import torch
    from threadpoolctl import threadpool_limits

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpool_limits(1):
            yield
    finally:
        torch.set_num_threads(threads)


@one_thread()
def bench_sanity(data: Path | None, out: Path | None, quick: bool) -> str:
    """Real held-out clips through the evaluation protocol: FID near zero and the recogniser's accuracy."""
    from refiner.evaluation.metrics import evaluate

    dataset, recognizer = _humanact12_and_recognizer(data, hidden="random")
    test, train = dataset.split("test"), dataset.split("train")
    n_rep, n = (3, 300) if quick else (20, 1000)
    lines = [f"## Evaluator sanity (HumanAct12 recogniser, {len(test)} test clips of subjects 11-12 vs "
             f"{len(train)} train clips)", "",
             f"Action2Motion protocol: {n} random 60-frame crops per side (with replacement), fresh N(0,1) GRU "
             f"hidden state per replication, {n_rep} replications, mean ± 1.96·σ/√R. 'matched' draws the "
             "reference crops with the same action mixture.", ""]
    rec = {"test_clips": len(test), "train_clips": len(train), "n_replications": n_rep, "n_crops": n,
           "comparisons": {}}
    for label, gen, ref, match in (("test vs train", test, train, False),
                                   ("test vs train, matched", test, train, True),
                                   ("train vs train, matched (floor)", train, train, True)):
        t0 = time.perf_counter()
        ev = evaluate(recognizer, gen.motions, ref.motions, n_replications=n_rep, n_generated=n, n_real=n,
                      match_labels=match, random_state=0)
        s = ev.summary()
        rec["comparisons"][label] = {"metrics": _metrics(s), "seconds": time.perf_counter() - t0}
        print(f"  {label}: FID {s['fid'][0]:.3f}, accuracy {100 * s['accuracy'][0]:.1f} %", flush=True)
    rows = [[label, _pm(c["metrics"]["fid"]), _pm(c["metrics"]["accuracy"], 100, ".1f")]
            + [_pm(c["metrics"][k]) for k in ("diversity", "multimodality", "real_diversity")] + [f"{c['seconds']:.1f}"]
            for label, c in rec["comparisons"].items()]
    write_record(out, "sanity", rec)
    lines.append(markdown_table(["comparison", "FID", "accuracy %", "diversity", "multimodality",
                                 "reference diversity", "seconds"], rows))
    return "\n".join(lines)


@one_thread()
def bench_generators(data: Path | None, out: Path | None, quick: bool) -> str:
    """The shipped reference generators' samples before and after refinement, scored by the HumanAct12 recogniser."""
    from refiner.refinement.pipeline import Refiner

    dataset, recognizer = _humanact12_and_recognizer(data, hidden="random")
    real = dataset.split("test")
    refiner = Refiner.pretrained("humanact12", split="train")
    # the paper's Table 1 protocol: 3,000 samples (250 per action), 20 replications
    per_action, n_rep = (3, 2) if quick else (250, 20)
    return _bench_generators(dataset, recognizer, real, refiner, per_action, n_rep, out)


def _bench_generators(dataset, recognizer, real, refiner, per_action: int, n_rep: int, out: Path | None) -> str:
    from refiner.evaluation.metrics import evaluate
    from refiner.reference import GENERATOR_KINDS, load_reference_generator

    n_actions = len(dataset.action_names)
    lines = [f"## Reference generators (HumanAct12; {per_action} samples per action, refiner trained on subjects "
             f"1-10, reference: {len(real)} clips of subjects 11-12)", "",
             "Both generators were trained on subjects 1-10 (`motion-refiner train-generator`). Each sample is "
             "converted by the `action2motion` adapter and refined with its sampled action by "
             "`Refiner.pretrained(split=\"train\")`. Metrics follow the Action2Motion protocol "
             f"(`refiner.evaluation.metrics.evaluate`, random GRU hidden state, {n_rep} replications, mean ± 95 % interval), "
             "real crops drawn with the generated action mixture. Accuracy is the recogniser's on the samples.", ""]
    rec = {"per_action": per_action, "n_replications": n_rep, "reference_clips": len(real), "rows": {}}
    for kind in GENERATOR_KINDS:
        gen = load_reference_generator(kind)
        before = [m for a in range(n_actions)
                  for m in gen.sample_motions(a, per_action, random_state=1000 * a + 7)]
        t0 = time.perf_counter()
        joints, reports = refiner.refine(np.stack([m.joints for m in before]), action=[m.action for m in before],
                                         return_report=True)
        seconds = time.perf_counter() - t0
        after = [m.with_joints(j) for m, j in zip(before, joints)]
        for label, motions in (("generated", before), ("refined", after)):
            s = evaluate(recognizer, motions, real.motions, n_replications=n_rep, match_labels=True,
                         random_state=0).summary()
            row = rec["rows"][f"{kind}/{label}"] = {"samples": len(motions), "metrics": _metrics(s)}
            if label == "refined":
                row.update(frames_changed=float(np.mean([r.changed_frames.mean() for r in reports])),
                           flagged_anchors_per_clip=float(np.mean([len(r.flagged_anchors) for r in reports])),
                           refine_seconds_per_clip=seconds / len(before))
            print(f"  {kind} {label}: accuracy {100 * s['accuracy'][0]:.1f} %, FID {s['fid'][0]:.3f}", flush=True)
    s = evaluate(recognizer, dataset.split("train").motions, real.motions, n_replications=n_rep,
                 n_generated=per_action * n_actions, match_labels=True, random_state=0).summary()
    rec["rows"]["real"] = {"samples": per_action * n_actions, "metrics": _metrics(s)}
    rows = []
    for key, r in rec["rows"].items():
        m = r["metrics"]
        rows.append(["real clips (subjects 1-10)", "real"] if key == "real" else key.split("/"))
        rows[-1] += [_pm(m["accuracy"], 100, ".1f"), _pm(m["fid"]), f"{m['diversity'][0]:.3f}",
                     f"{m['multimodality'][0]:.3f}"]
        rows[-1] += [f"{100 * r['frames_changed']:.1f}", f"{r['flagged_anchors_per_clip']:.2f}",
                     f"{r['refine_seconds_per_clip']:.2f}"] if "frames_changed" in r else ["", "", ""]
    lines.append(markdown_table(["generator", "samples", "accuracy %", "FID", "diversity", "multimodality",
                                 "frames changed %", "flagged anchors / clip", "refine s / clip"], rows))
    write_record(out, "generators", rec)
    return "\n".join(lines)


def _moved(name: str) -> Callable[..., str]:
    """A suite in another module (see ``_ELSEWHERE``), imported when it runs."""
    def run(data: Path | None, out: Path | None, quick: bool, **kwargs) -> str:
        return __getattr__(name)(data, out, quick, **kwargs)

    run.__name__ = run.__qualname__ = name
    return run


SUITES: dict[str, Callable[[Path | None, Path | None, bool], str]] = {
    "concepts": bench_concepts,
    "refiner": _moved("bench_refiner"),
    "speed": _moved("bench_speed"),
    "sanity": bench_sanity,
    "flaws": _moved("bench_flaws"),
    "samples": _moved("bench_samples"),
    "skeletons": _moved("bench_skeletons"),
    "generators": bench_generators,
}


def run_benchmarks(suite: str, *, data: Path | None = None, out: Path | None = None, quick: bool = False,
                   stride: int = 1, severities: tuple[int, ...] | None = None) -> int:
    names = list(SUITES) if suite == "all" else [suite]
    sections = []
    for name in names:
        extra = ({"stride": stride, "severities": severities} if name == "flaws"
                 else {"stride": stride} if name == "skeletons" and stride > 1 else {})
        section = SUITES[name](data, out, quick, **extra)
        print(section, flush=True)
        print(flush=True)
        sections.append(section)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "REPORT.md").write_text("# motion-refiner benchmark report\n\n" + "\n\n".join(sections) + "\n")
        print(f"report written to {out / 'REPORT.md'}")
    return 0
