"""The Markdown sections and progress lines ``motion-refiner bench`` prints, made from the suites' records.

:data:`SECTIONS` maps a suite name to ``record -> str`` (the section printed and collected into
``REPORT.md``), :data:`PROGRESS` a ``(suite, event)`` pair to ``payload -> str`` (a line printed while
the suite runs). The records are described in each suite's module (:mod:`refiner.evaluation.bench`).
"""
from __future__ import annotations

import json
from typing import Callable

__all__ = ["markdown_table", "SECTIONS", "PROGRESS"]


def markdown_table(header: list[str], rows: list[list]) -> str:
    """A Markdown table; floats with three decimals."""
    def fmt(v):
        return f"{v:.3f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def _pm(value: list, scale: float = 1.0, spec: str = ".3f") -> str:
    """``[mean, half-width]`` as the tables print it, ``mean ± half-width``."""
    return f"{scale * value[0]:{spec}} ± {scale * value[1]:{spec}}"


def _parameters(counts: dict) -> str:
    return ", ".join(f"{k} {v:,}" for k, v in counts.items())


# ----------------------------------------------------------------------------------------------
# concepts


def _concepts_segmented(rec: dict) -> str:
    return (f"Segmenting all {rec['clips']} clips at λ={rec['penalty']:g}: **{rec['segment_seconds']:.1f} s** "
            f"wall on this machine (target: 30 s or less for 1,191 clips).")


def _concepts_penalty(r: dict) -> str:
    return (f"  λ={r['penalty']:g}: {r['transitions_per_clip']:.2f} transitions/clip, {r['mean_transition_frames']:.1f} "
            f"frames each, MPJPE {r['mpjpe_cm']:.3f} cm")


def _concepts(rec: dict) -> str:
    rows = [[f"{r['penalty']:g}", r["transitions_per_clip"], r["mean_transition_frames"], r["mpjpe_cm"],
             r["mpjpe_mean_of_actions_cm"], r["paper_mpjpe_cm"]] for r in rec["penalties"]]
    clusters = list(rec["kmeans"][0]["distance_cm"]) if rec["kmeans"] else []
    krows = [[r["action"], r["anchors"]] + ["-" if v is None else v for v in r["distance_cm"].values()]
             for r in rec["kmeans"]]
    return "\n".join([
        f"## Concepts (HumanAct12, {rec['clips']} clips, {rec['frames']} frames)", "", _concepts_segmented(rec),
        "", "λ in cm² per joint (see `refiner.concepts.segmentation`). MPJPE of the spline reconstruction, cm.", "",
        markdown_table(["λ", "transitions / clip", "mean transition frames", "MPJPE (all frames)",
                        "MPJPE (mean of actions)", "paper Table 2 MPJPE"], rows),
        "", "Anchor K-means: mean joint distance to the assigned centre (cm) by number of clusters.", "",
        markdown_table(["action", "anchors"] + [f"k={k}" for k in clusters], krows)])


# ----------------------------------------------------------------------------------------------
# refiner and speed


def _refiner_figures(rec: dict) -> str:
    b = rec["boundary_acceleration"]
    return markdown_table(["figure", "value", "target"], [
        ["(a) real clips: MPJPE change (cm)", rec["real_mpjpe_change_cm"], "< 0.3"],
        ["(a) real clips changed at all", f"{rec['real_clips_changed']} / {rec['clips']}", ""],
        ["(b) largest boundary acceleration (m/s²), refined drifted clips",
         "no boundary" if b["max"] is None else b["max"], f"real p99 {b['real_p99']:.1f}"],
        ["(b) median boundary acceleration (m/s²)", "-" if b["median"] is None else b["median"], ""],
        ["(b) boundaries above real p99", f"{b['above_real_p99']} / {b['boundaries']}", ""],
        ["(c) anchor recognition precision (±2 frames)", rec["anchor_precision"], ""],
        ["(c) anchor recognition recall (±2 frames)", rec["anchor_recall"], ""],
    ])


def _refiner_latency(rec: dict) -> str:
    lat = rec["latency"]
    return (f"(d) refine latency per 60-frame clip, CPU batch 1 ({lat['threads']} threads, "
            f"{lat['clips']} clips): median **{lat['median_ms']:.1f} ms**, "
            f"90th percentile {lat['p90_ms']:.1f} ms (paper: 17 ms on a GPU).")


def _refiner(rec: dict) -> str:
    rows = [[family, v["pose"], v["encoder"]] for family, v in rec["anchor_quality_auc"].items()]
    return "\n".join([
        f"## Refiner (the default motion model, {rec['clips']} held-out clips of subjects 11-12)", "",
        "Parameters: " + _parameters(rec["parameters"]) + " (paper: 6.23 M). (c) and the anchor scores below are the "
        "concepts method's (subject-1-10 weights).",
        "", _refiner_figures(rec), "", _refiner_latency(rec),
        "", "Anchor quality scores, ROC AUC separating a seeded flawed anchor (severity 2) from a real one:", "",
        markdown_table(["flaw", "pose mixture (default)", "encoder-feature GMM (paper)"], rows)])


def _speed_device(d: dict) -> str:
    return f"  {d['device']}: median {d['median_ms']:.1f} ms per 60-frame clip"


def _speed_lengths(rows: list) -> list:
    if not rows:
        return []
    return ["", "Cost by clip length (batch 1, one clip played back and forth):", "",
            markdown_table(["frames", "ms / clip", "µs / frame"], [[r["frames"], r["median_ms"], r["us_per_frame"]] for r in rows])]


def _speed(rec: dict) -> str:
    rows = [[d["device"], d["name"], d["median_ms"], d["p90_ms"], d["clips_per_s"],
             f"{d['peak_mib']:.0f} MiB ({d['peak_of']})"] for d in rec["devices"]]
    cuda = any(d["device"] == "cuda" for d in rec["devices"])
    return "\n".join([
        f"## Speed ({rec['clips']} held-out 60-frame clips; paper: 0.017 s per clip, 6.23 M parameters)", "",
        markdown_table(["device", "", "median ms / clip (batch 1)", "p90 ms", f"clips / s (batch of {rec['batch']})",
                        "peak memory"], rows),
        *_speed_lengths(rec.get("lengths", [])),
        "", "Parameters: " + _parameters(rec["parameters"]) + ".",
        "" if cuda else "The default refiner's motion model runs on the CPU.",
    ])


# ----------------------------------------------------------------------------------------------
# sanity and generators (the Action2Motion protocol)


def _sanity_comparison(c: dict) -> str:
    return f"  {c['label']}: FID {c['metrics']['fid'][0]:.3f}, accuracy {100 * c['metrics']['accuracy'][0]:.1f} %"


def _sanity(rec: dict) -> str:
    rows = [[label, _pm(c["metrics"]["fid"]), _pm(c["metrics"]["accuracy"], 100, ".1f")]
            + [_pm(c["metrics"][k]) for k in ("diversity", "multimodality", "real_diversity")] + [f"{c['seconds']:.1f}"]
            for label, c in rec["comparisons"].items()]
    return "\n".join([
        f"## Evaluator sanity (HumanAct12 recogniser, {rec['test_clips']} test clips of subjects 11-12 vs "
        f"{rec['train_clips']} train clips)", "",
        f"Action2Motion protocol: {rec['n_crops']} random 60-frame crops per side (with replacement), fresh N(0,1) GRU "
        f"hidden state per replication, {rec['n_replications']} replications, mean ± 1.96·σ/√R. 'matched' draws the "
        "reference crops with the same action mixture.", "",
        markdown_table(["comparison", "FID", "accuracy %", "diversity", "multimodality", "reference diversity",
                        "seconds"], rows)])


def _generators_row(r: dict) -> str:
    m = r["metrics"]
    return f"  {r['kind']} {r['label']}: accuracy {100 * m['accuracy'][0]:.1f} %, FID {m['fid'][0]:.3f}"


def _generators(rec: dict) -> str:
    rows = []
    for key, r in rec["rows"].items():
        m = r["metrics"]
        rows.append(["real clips (subjects 1-10)", "real"] if key == "real" else key.split("/"))
        rows[-1] += [_pm(m["accuracy"], 100, ".1f"), _pm(m["fid"]), f"{m['diversity'][0]:.3f}",
                     f"{m['multimodality'][0]:.3f}"]
        phys = r.get("physics")
        rows[-1] += [f"{phys['acceleration']:.2f}", f"{100 * phys['foot_skating']:.1f}",
                     f"{100 * phys['bone_length_variation']:.2f}"] if phys else ["", "", ""]
        rows[-1] += [f"{100 * r['frames_changed']:.1f}", f"{r['changes_per_clip']:.2f}",
                     f"{r['refine_seconds_per_clip']:.2f}"] if "frames_changed" in r else ["", "", ""]
    return "\n".join([
        f"## Reference generators (HumanAct12; {rec['per_action']} samples per action, default refiner, "
        f"reference: {rec['reference_clips']} clips of subjects 11-12)", "",
        "The generators were trained on subjects 1-10 (`motion-refiner train-generator`). Each sample is "
        "converted by the `action2motion` adapter and refined with its sampled action by the default refiner, "
        "`MotionRefiner.pretrained()` (its model learned on subjects 1-8). "
        "Metrics follow the Action2Motion protocol "
        f"(`refiner.evaluation.metrics.evaluate`, random GRU hidden state, {rec['n_replications']} replications, "
        "mean ± 95 % interval), real crops drawn with the generated action mixture. Accuracy is the recogniser's on "
        "the samples.", "",
        markdown_table(["generator", "samples", "accuracy %", "FID", "diversity", "multimodality",
                        "acceleration m/s²", "foot skating %", "bone-length variation %",
                        "frames changed %", "changes / clip", "refine s / clip"], rows)])


# ----------------------------------------------------------------------------------------------
# flaws, samples, skeletons


def _flaws(rec: dict) -> str:
    families, records = rec["families"], rec["flawed"]
    names = list(dict.fromkeys(r["refiner"] for r in records))
    table = {(r["family"], r["severity"], r["refiner"]): r for r in records}
    lines = [f"## Flaws (HumanAct12 subjects 11-12, {rec['clips']} clips, severities {rec['severities']})", "",
             "Share of the flaw's added MPJPE removed (%, all frames, against the clean clip; negative = worse "
             "than leaving the flaw). `ours_full` is the default refiner (the motion model), the other `ours_*` the "
             "concepts method. Oracle rows get the true flaw mask.", ""]
    notes = [f"- `{name}` skipped: {why}" for name, why in rec["skipped"].items()]
    lines += notes + ([""] if notes else [])
    for severity in rec["severities"]:
        summary = rec["summary"][str(severity)]
        rows = [[name] + [float(table[(f, severity, name)]["removed_pct"]) for f in families]
                + [summary[name]["mean_removed_pct"]] for name in names]
        lines += [f"### Severity {severity}: % of added MPJPE removed", "",
                  markdown_table(["refiner"] + list(families) + [f"mean, all {len(families)}"], rows), ""]
        mrows = [[name] + [float(table[(f, severity, name)]["mpjpe_cm"]) for f in families] for name in names]
        lines += [f"### Severity {severity}: MPJPE (cm, all frames; `identity` = the flaw)", "",
                  markdown_table(["refiner"] + list(families), mrows), ""]
        frows = [[name] + [float(table[(f, severity, name)]["mpjpe_flawed_cm"]) for f in families]
                 for name in names]
        lines += [f"### Severity {severity}: MPJPE on the flawed frames only (cm)", "",
                  markdown_table(["refiner"] + list(families), frows), ""]
    clean_rows = [[name, c["mpjpe_change_cm"], c["share_changed"]] for name, c in rec["clean"].items()]
    lines += ["### Clean held-out clips (do no harm)", "",
              markdown_table(["refiner", "MPJPE change cm", "share of clips changed"], clean_rows), "",
              f"{rec['seconds']:.0f} s wall."]
    return "\n".join(lines)


def _samples_part(title: str, recogniser: str, rec: dict, accuracy_target: str) -> list[str]:
    """The markdown lines of one set of samples' :func:`~refiner.evaluation.bench_samples.sample_records`."""
    g, r = rec["generated"], rec["refined"]
    rows = [[f"{recogniser} recogniser accuracy %", 100 * g["accuracy"], 100 * r["accuracy"], accuracy_target],
            ["bone-length variation % (std / mean per bone)", 100 * g["bone_length_variation"],
             100 * r["bone_length_variation"], "under 1"],
            ["mean joint acceleration (m/s²)", g["acceleration"], r["acceleration"], ""],
            ["frames changed % (any step)", "", 100 * rec["frames_changed"], ""],
            ["frames repaired % (flaw repair only)", "", 100 * rec["repaired_frames"], ""]]
    return [f"## {title}", "", markdown_table(["figure", "generated", "refined", "target"], rows), "",
            "Changes by step (over all clips): " + (", ".join(f"{k} {v}" for k, v in rec["changes_by_step"].items())
                                                  or "none") + ".", "",
            *([f"The concepts method with its concept-snap option (`concept_snap=1`): accuracy "
               f"{100 * rec['snapped']['accuracy']:.2f} %, "
               f"bone-length variation {100 * rec['snapped']['bone_length_variation']:.3f} %, "
               f"{100 * rec['snapped']['frames_changed']:.0f} % of frames changed.", ""] if "snapped" in rec else []),
            "First clip's report: " + (json.dumps(rec["reports"][0]["changes"]) if rec["reports"] else "-")]


def _samples(rec: dict) -> str:
    if "skipped" in rec:
        return f"## Real generator samples\n\n({rec['skipped']}; skipped)"
    lines = _samples_part(f"Real generator samples (Action2Motion xyz VAE, {len(rec['reports'])} clips, default "
                          "refiner)", "HumanAct12", rec, "at least 85")
    if "ntu13" in rec:
        ntu = rec["ntu13"]
        lines += [""] + _samples_part(f"NTU13 samples (Action2Motion xyz VAE, 18 joints, skeleton 'uestc', "
                                      f"{ntu['clips']} clips; refined through HumanAct12's motion model with the "
                                      "action unknown)", "NTU13", ntu, "not lower")
    else:
        lines += ["", f"({rec['ntu13_skipped']})"]
    return "\n".join(lines)


def _skeletons(rec: dict) -> str:
    rows_by = rec["skeletons"]
    names = list(next(iter(rows_by.values()))["removed_pct"])
    rows = [[s, r["clean_mpjpe_change_cm"], r["clean_clips_changed"], *[r["removed_pct"][f] for f in names],
             r["mean_removed_pct"]] for s, r in rows_by.items()]
    rows = [[s, r.get("weights", ""), *row[1:]] for (s, r), row in zip(rows_by.items(), rows)]
    lines = [
        f"## Skeletons (HumanAct12 subjects 11-12, every {rec['stride']}th clip: {rec['clips']} clips, "
        "converted to each layout; severity 2; action unknown)", "",
        "The default refiner, `MotionRefiner.pretrained(skeleton)`. `weights`: the skeleton whose motion model refines "
        "it (`humanact12, converted`: through HumanAct12's, converted in and the change converted back). A skeleton "
        "whose model was trained on another dataset scores motion it never saw here (a transfer figure); a section "
        "below scores its model's own held-out subjects.", "",
        markdown_table(["skeleton", "weights", "clean: MPJPE change cm", "clean: share of clips changed",
                        *[f"{f}: % removed" for f in names], "mean % removed"], rows)]
    for skel, r in rec.get("native", {}).items():
        fams = list(r["removed_pct"])
        acc = r["accuracy_pct"]
        lines += ["", f"### {skel} on its own data ({r['dataset']} held-out subjects, {r['clips']} clips cut to their "
                  "first frames; flaws seeded in its layout, severity 2; action unknown)", "",
                  markdown_table(["clean: MPJPE change cm", "clean: share of clips changed",
                                  *[f"{f}: % removed" for f in fams], "mean % removed"],
                                 [[r["clean_mpjpe_change_cm"], r["clean_clips_changed"],
                                   *[r["removed_pct"][f] for f in fams], r["mean_removed_pct"]]]), "",
                  f"{r['dataset']} recogniser accuracy: clean {acc['clean']:.1f} %, flawed {acc['flawed']:.1f} %, "
                  f"refined {acc['refined']:.1f} % (mean over families). Weights' licence: {r['licence']}"]
    skipped = [f"- `{skel}` skipped: {why}" for skel, why in rec.get("skipped", {}).items()]
    lines += [""] + skipped if skipped else []
    return "\n".join(lines + ["", f"{rec['seconds']:.0f} s wall."])


# ----------------------------------------------------------------------------------------------
# noharm


def _noharm_figures(row: dict) -> list:
    acc = row.get("accuracy_pct")
    return [f"{row['jerk']:.1f}", f"{100 * row['foot_skating']:.2f}", f"{row['penetration_cm']:.3f}",
            f"{row['floating_cm']:.2f}", f"{row['bone_length_variation_pct']:.2f}",
            "-" if acc is None else f"{acc:.1f} ± {row['accuracy_std_pct']:.1f}"]


_NOHARM_RULES = {"relative": "{} after > before × (1 + {:g})", "up": "{} after > before + {:g}",
                 "level": "{} after > before and ≥ {:g}", "down": "{} after < before − {:g}"}


def _noharm_set(payload: dict) -> str:
    v = payload["verdict"]["violated"]
    return f"  {payload['name']}: " + (f"worse after refinement: {', '.join(v)}" if v else "no harm")


def _noharm(rec: dict) -> str:
    header = ["set", "row", "clips", "jerk m/s³", "foot skating %", "penetration cm", "floating cm",
              "bone-length variation %", "accuracy %", "cm moved", "cm moved (changed frames)", "frames changed %",
              "clips changed %", "seconds", "worse after"]
    rows = []
    for name, s in rec["sets"].items():
        a = s["after"]
        rows.append([name, "before", s["clips"], *_noharm_figures(s["before"])] + [""] * 6)
        rows.append([name, "after", s["clips"], *_noharm_figures(a), f"{a['cm_moved']:.3f}",
                     f"{a['cm_moved_changed_frames']:.3f}", f"{100 * a['frames_changed']:.1f}",
                     f"{100 * a['clips_changed']:.1f}", f"{a['seconds']:.2f}",
                     ", ".join(s["verdict"]["violated"]) or "none"])
    for skel, r in rec["real"].items():
        rows.append([f"real {skel}", r.get("source", r.get("none", "")), r.get("clips", "-"),
                     *(_noharm_figures(r) if "jerk" in r else ["-"] * 6)] + [""] * 6)
    t = rec["thresholds"]
    notes = [f"- `{n}`: {s['note']}" for n, s in rec["sets"].items() if s["note"]]
    notes += [f"- `{n}` skipped: {why}" for n, why in rec["skipped"].items()]
    return "\n".join([
        f"## No harm (generated clips before and after refinement; refiner {rec['refiner']})", "",
        f"Means over clips at {t['fps']:g} fps. Foot skating: share of frame pairs in which a foot within "
        f"{100 * t['contact_height_m']:g} cm of the ground (both frames) moves faster than "
        f"{t['skating_speed_m_s']:g} m/s horizontally, in the pair and over {t['skating_window_frames']} pairs "
        "(GMD). Ground: the lowest height a clip's ankles and feet reach; after rows use the before clip's. "
        "Floating: lowest joint above the ground "
        f"less {1000 * t['floating_tolerance_m']:g} mm. Accuracy: the set's Action2Motion recogniser, mean ± std over "
        f"{rec['n_hidden']} random hidden states. A frame is changed when a joint moved more than "
        f"{1000 * t['changed_frame_m']:g} mm. Worse after (verdict): " + "; ".join(
            _NOHARM_RULES[r["kind"]].format(k, r["tolerance"]) for k, r in rec["tolerances"].items()) + ".", "",
        markdown_table(header, rows), "", *notes, *([""] if notes else []), f"{rec['seconds']:.0f} s wall."])


# ----------------------------------------------------------------------------------------------
# heldout


def _heldout_row(name: str, r: dict) -> list:
    return [name, r.get("family", "blind"), r["weights"], f"{r['added_cm']:.2f}", f"{r['refined']:+.1f}",
            f"{r['linear']:+.1f}", "0.0", f"{100 * r['clips_touched']:.0f}"]


def _heldout(rec: dict) -> str:
    header = ["mechanism", "family", "weights (never saw it)", "added error cm", "refined: % removed",
              "linear in-fill, same flags", "as given", "clips touched %"]
    rows = [_heldout_row(n, r) for n, r in rec["mechanisms"].items()] + [_heldout_row(n, r) for n, r in rec["blind"].items()]
    fams = ", ".join(f"{f} {v:+.1f}" for f, v in rec["families"].items())
    clean = "; ".join(f"{n}: {c['cm_moved']:.3f} cm, {100 * c['clips_touched']:.1f} % of clips touched" for n, c in rec["clean"].items())
    return "\n".join([
        f"## Held-out mechanisms (HumanAct12 subjects 11-12, {rec['clips']} clips)", "",
        "Each mechanism is scored with the weights trained and calibrated without its fold; blind mechanisms (written "
        "by someone who had not read the refiner) with the default weights. % of the added MPJPE removed.", "",
        markdown_table(header, rows), "",
        f"**Mean over held-out mechanisms: {rec['heldout_mean']:+.1f} %** (linear in-fill on the same flags "
        f"{rec['linear_mean']:+.1f} %). Families: {fams}.", "", f"Clean clips: {clean}."])


def _heldout_mechanism(payload: dict) -> str:
    return f"  {payload['name']}: {payload['refined']:+.1f} % removed (linear {payload['linear']:+.1f} %)"


def _corpus_row(r: dict) -> str:
    return f"  {r['name']}: {r['clips_per_s']:.1f} clips/s ({r['wall_s']:.1f} s from start to exit)"


def _corpus(rec: dict) -> str:
    rows = [[r["name"], f"{r['wall_s']:.1f}", f"{r['clips_per_s']:.1f}",
             f"{r['pipeline_clips_per_s']:.1f}" if "pipeline_s" in r else "-"] for r in rec["rows"]]
    return "\n".join([f"## Corpus refinement ({rec['clips']} clips of {rec['frames'] // rec['clips']} frames in {rec['shards']} "
                      f"shards, {rec['cpus']} CPUs)", "", "Each command in a fresh process, from start to exit; the Ray "
                      "rows start a local Ray (the last column: from the pipeline's start, Ray running).", "",
                      markdown_table(["command", "seconds", "clips/s", "clips/s, pipeline"], rows), *rec["notes"]])


#: Suite name -> the Markdown section of its record.
SECTIONS: dict[str, Callable[[dict], str]] = {
    "concepts": _concepts,
    "refiner": _refiner,
    "speed": _speed,
    "sanity": _sanity,
    "flaws": _flaws,
    "samples": _samples,
    "skeletons": _skeletons,
    "generators": _generators,
    "noharm": _noharm,
    "heldout": _heldout,
    "corpus": _corpus,
}

#: ``(suite, progress event)`` -> the line printed for its payload; events without an entry print nothing.
PROGRESS: dict[tuple[str, str], Callable[[dict], str]] = {
    ("concepts", "segmented"): _concepts_segmented,
    ("concepts", "penalty"): _concepts_penalty,
    ("refiner", "figures"): _refiner_figures,
    ("refiner", "latency"): _refiner_latency,
    ("speed", "device"): _speed_device,
    ("sanity", "comparison"): _sanity_comparison,
    ("generators", "row"): _generators_row,
    ("noharm", "set"): _noharm_set,
    ("heldout", "mechanism"): _heldout_mechanism,
    ("corpus", "row"): _corpus_row,
}
