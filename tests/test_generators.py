"""RefinedGenerator: sampling through the generator's own API, conversion by adapter, refinement."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from refiner import RefinedGenerator
from refiner.adapters.action2motion import lie_to_joints
from refiner.core.motion import Motion

REST = np.asarray(lie_to_joints(np.zeros((1, 72)), recenter=False)[0])


class XyzVae:
    """Stands in for Action2Motion's xyz VAE: ``sample(action, n)`` -> (n, 60, 72), root not at the origin."""

    def __init__(self):
        self.calls = []

    def sample(self, action, n=1, **kwargs):
        self.calls.append((action, n, kwargs))
        t = np.arange(60)[:, None, None] * np.array([0.0, 0.0, -0.01])
        joints = REST * np.array([1.0, -1.0, -1.0]) + t + np.array([0.1, 0.2, 0.3])
        return np.repeat(joints[None], n, axis=0).reshape(n, 60, 72).astype(np.float32)


class IdentityRefiner:
    def __init__(self):
        self.seen = []

    def refine(self, motion, *, action=None, return_report=False):
        self.seen.append(action)
        return (motion, {"changed": 0}) if return_report else motion


class LiftingRefiner:
    """Moves every joint 5 cm up (-y) and reports it: a refiner whose effect a test can see."""

    def refine(self, motion, *, action=None, return_report=False):
        out = motion.with_joints(motion.joints - np.array([0.0, 0.05, 0.0], dtype=np.float32))
        return (out, {"lifted_m": 0.05, "action": action}) if return_report else out


@pytest.fixture
def xyz_options():
    return {"representation": "xyz"}


def test_identity_refiner_returns_converted_samples(pm, xyz_options):
    vae, refiner = XyzVae(), IdentityRefiner()
    gen = RefinedGenerator(vae, adapter="action2motion", refiner=refiner, adapter_options=xyz_options, plugin_manager=pm)
    motions, raw, reports = gen.sample(3, n=2, return_raw=True, return_report=True, temperature=0.5)
    assert vae.calls == [(3, 2, {"temperature": 0.5})]  # kwargs go to the generator
    assert raw.shape == (2, 60, 72) and reports == [{"changed": 0}] * 2 and refiner.seen == [3, 3]
    for m, r in zip(motions, raw):
        assert isinstance(m, Motion) and m.skeleton == "humanact12" and m.action == 3
        np.testing.assert_array_equal(m.joints, r.reshape(60, 24, 3))  # xyz: unchanged
    assert gen.sample(0) and len(gen.sample(0, n=4)) == 4


def test_modifying_refiner_is_applied(pm, xyz_options):
    gen = RefinedGenerator(XyzVae(), adapter="action2motion", refiner=LiftingRefiner(), adapter_options=xyz_options,
                           plugin_manager=pm)
    motions, raw = gen.sample("walk", n=2, return_raw=True)
    converted = pm.convert("action2motion", raw, options=xyz_options)
    for m, c in zip(motions, converted):
        np.testing.assert_allclose(c.joints - m.joints, np.broadcast_to([0.0, 0.05, 0.0], m.joints.shape), atol=1e-6)
        assert m.action == 1  # "walk" is HumanAct12 class 1
    _, reports = gen.sample(5, return_report=True)
    assert reports == [{"lifted_m": 0.05, "action": 5}]


def test_plain_callables_as_generator_and_refiner(pm):
    def generator(action, n=1, scale=1.0):
        return np.random.default_rng(action).normal(size=(n, 60, 72)).astype(np.float32) * 0.3 * scale

    flip = RefinedGenerator(generator, adapter="action2motion", refiner=lambda m: m.with_joints(m.joints[::-1]),
                            adapter_options={"representation": "lie"}, plugin_manager=pm)
    motions, reports = flip.sample(7, n=3, scale=0.5, return_report=True)
    assert reports == [None, None, None]
    expected = pm.convert("action2motion", generator(7, n=3, scale=0.5), options={"representation": "lie"})
    for m, e in zip(motions, expected):
        np.testing.assert_allclose(m.joints, e.joints[::-1], atol=1e-6)
        assert m.action == 7


def test_default_refiner_falls_back_to_identity_when_pipeline_missing(pm, monkeypatch, xyz_options):
    # makes `import refiner.refinement.motion_refiner` fail
    monkeypatch.setitem(sys.modules, "refiner.refinement.motion_refiner", None)
    with pytest.warns(UserWarning, match="default refiner"):
        gen = RefinedGenerator(XyzVae(), adapter="action2motion", adapter_options=xyz_options, plugin_manager=pm)
    m = gen.sample(2)[0]
    np.testing.assert_array_equal(m.joints, XyzVae().sample(2)[0].reshape(60, 24, 3))


def test_default_refiner_is_the_pretrained_motion_refiner(pm, monkeypatch, xyz_options):
    """With refiner.refinement.motion_refiner importable, MotionRefiner.pretrained(skeleton) is what gets used."""
    import types

    from refiner.refinement.motion_refiner import MotionRefiner

    gen = RefinedGenerator(XyzVae(), adapter="action2motion", adapter_options=xyz_options, plugin_manager=pm)
    assert isinstance(gen.refiner, MotionRefiner) and gen.refiner.method == "motion"
    assert gen.refiner.skeleton == "humanact12" and "MotionRefiner" in repr(gen)
    motions, reports = gen.sample(2, n=1, return_report=True)
    assert motions[0].joints.shape == (60, 24, 3) and reports[0].action == 2 and reports[0].flaw_probability

    calls = []

    class FakeRefiner:
        @classmethod
        def pretrained(cls, skeleton, **options):
            calls.append((skeleton, options))
            return LiftingRefiner()

    monkeypatch.setitem(sys.modules, "refiner.refinement.motion_refiner", types.SimpleNamespace(MotionRefiner=FakeRefiner))
    gen = RefinedGenerator(XyzVae(), adapter="action2motion", adapter_options=xyz_options, plugin_manager=pm)
    assert calls == [("humanact12", {})] and isinstance(gen.refiner, LiftingRefiner)

    class NoWeights:
        @classmethod
        def pretrained(cls, skeleton, **options):
            raise ValueError("no motion model")

    monkeypatch.setitem(sys.modules, "refiner.refinement.motion_refiner", types.SimpleNamespace(MotionRefiner=NoWeights))
    with pytest.raises(ValueError, match=r"default refiner MotionRefiner.pretrained\('uestc'\) failed: no motion model"):
        RefinedGenerator(XyzVae(), adapter="action2motion", skeleton="uestc", plugin_manager=pm)


def test_skeleton_choice_and_adapter_recognition(pm):
    def ntu(action, n=1):
        return np.zeros((n, 60, 54), dtype=np.float32)

    gen = RefinedGenerator(ntu, adapter="action2motion", skeleton="uestc", refiner=lambda m: m,
                           adapter_options={"representation": "lie"}, plugin_manager=pm)
    assert gen.sample(0)[0].skeleton == "uestc"
    with pytest.raises(ValueError, match="no adapter recognises generator of type function.*action2motion"):
        RefinedGenerator(ntu, refiner=lambda m: m, plugin_manager=pm)


def test_bad_arguments_raise_clear_errors(pm, xyz_options):
    with pytest.raises(ValueError, match="unknown adapter 'a2m'; known adapters: action2motion"):
        RefinedGenerator(XyzVae(), adapter="a2m", refiner=lambda m: m, plugin_manager=pm)
    with pytest.raises(ValueError, match="cannot produce skeleton 'humanml3d'"):
        RefinedGenerator(XyzVae(), adapter="action2motion", skeleton="humanml3d", refiner=lambda m: m, plugin_manager=pm)
    with pytest.raises(TypeError, match="`refiner` must have a refine"):
        RefinedGenerator(XyzVae(), adapter="action2motion", refiner=42, plugin_manager=pm)
    gen = RefinedGenerator(XyzVae(), adapter="action2motion", refiner=lambda m: m, adapter_options=xyz_options,
                           plugin_manager=pm)
    for n in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="`n` must be a positive int"):
            gen.sample(1, n=n)
    bad = RefinedGenerator(XyzVae(), adapter="action2motion", refiner=lambda m: m.joints, adapter_options=xyz_options,
                           plugin_manager=pm)
    with pytest.raises(TypeError, match="must return a Motion"):
        bad.sample(1)
    missing = RefinedGenerator(XyzVae(), adapter="action2motion", refiner=lambda m: m, plugin_manager=pm)
    with pytest.raises(ValueError, match="representation"):
        missing.sample(1)
    with pytest.raises(TypeError, match="no sample\\(\\) method, is not callable"):
        RefinedGenerator(object(), adapter="action2motion", refiner=lambda m: m, plugin_manager=pm).sample(1)
    assert "adapter='action2motion'" in repr(gen)


def test_wrap_generator_example_runs():
    import subprocess
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "examples" / "wrap_generator.py"
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "adapter='toymotion'" in out.stdout and "the refiner moved joints by up to" in out.stdout
