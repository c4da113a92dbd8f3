"""Measure which repair serves each flaw group (the figures behind ``refiner.learned_pipeline.TYPED_REPAIRS``).

Usage: python examples/measure_typed_repairs.py REFINER_DIR   (e.g. refiner/weights/humanact12-train)

For every run the classifier flags on the calibration subjects (9-10) of the train split, with
synthetic training flaws of each group and the benchmark's training families (severity 2; never its
held-out families), the MPJPE change of every candidate repair against keeping the frames, summed per
flaw group the classifier names; the best candidate per group is printed last. It wraps the
pipeline's candidate selection to see every candidate; about a minute on one CPU core.
"""
import numpy as np, torch, sys, collections, json
torch.set_num_threads(1)
import refiner.learned_pipeline as lp
from refiner.pipeline import Refiner
from refiner.datasets import load_humanact12
from refiner.flaws import corrupt
from refiner.training_flaws import TRAINING_FAMILIES, GROUPS, synthesize
orig = lp._select
ROWS = []
def sel(refiner, y, spliced, lo, hi):
    names = ["keep", *spliced]; clips = np.stack([y, *spliced.values()])
    err = 100 * np.linalg.norm(clips - CLEAN, axis=-1).mean((1, 2))
    g = refiner.flaw_classifier.predict_all(y[None])[0, :, 1:]
    ROWS.append((SRC, int(np.argmax(g[lo:hi].mean(0))), dict(zip(names, err - err[0]))))
    return orig(refiner, y, spliced, lo, hi)
lp._select = sel
m = Refiner.load(sys.argv[1], repair="select")
ds = load_humanact12().split('train'); held = np.isin(ds.subjects, [9, 10])
clips = [c for c, h in zip(ds.motions, held) if h]
rng = np.random.default_rng(5)
for SRC in list(GROUPS) + list(TRAINING_FAMILIES) + ["clean"]:
    for i, c0 in enumerate(clips):
        CLEAN = c0.joints
        if SRC == "clean" or len(c0.joints) < 8:
            m.refine(c0.joints, action=c0.action)
        elif SRC in GROUPS:
            f = synthesize(c0.joints, rng, kinds=GROUPS[SRC], clean_probability=0, max_flaws=1,
                           donors=[clips[(i + 3) % len(clips)].joints])
            m.refine(f.joints, action=c0.action)
        elif i % 2 == 0:
            donors = [d for d in clips if d.action == c0.action and d is not c0]
            m.refine(corrupt(c0, SRC, 2, random_state=1000 + i, donors=donors).motion.joints, action=c0.action)
names = list(ROWS[0][2]); G = list(GROUPS); choice = {}
for g in range(len(G)):
    rows = [r for r in ROWS if r[1] == g]
    tot = {n: sum(r[2].get(n, r[2].get(n.split(' (')[0], 0.0)) for r in rows) for n in names}
    best = min(tot, key=tot.get); choice[G[g]] = best
    print(G[g], len(rows), dict(collections.Counter(r[0] for r in rows)))
    print("   ", ", ".join(f"{n}: {v:+.1f}" for n, v in sorted(tot.items(), key=lambda kv: kv[1])[:6]))
print(json.dumps(choice))
