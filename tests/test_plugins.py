"""The plugin machinery: hook specs, built-in adapters as plugins, entry-point plugins, broken plugins."""
from __future__ import annotations

import inspect
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pluggy
import pytest

from refiner.core.skeletons import list_skeletons
from refiner.plugins import BUILTIN_ADAPTERS, AdapterInfo, get_plugin_manager, hookimpl, hookspecs
from refiner.plugins.manager import DISABLE_AUTOLOAD_ENV, AdapterPluginWarning, get_adapter, list_adapters

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "third_party_adapter"
HOOKS = ("refiner_adapter_info", "refiner_convert_output", "refiner_encode_motions", "refiner_recognize_generator",
         "refiner_sample_generator", "refiner_read_file", "refiner_write_refined")


def make_distribution(root: Path, name: str, entry_points: dict[str, str], modules: dict[str, str] | None = None):
    """An installed-looking distribution: ``<name>-0.1.0.dist-info`` with entry points, plus module files."""
    info = root / f"{name.replace('-', '_')}-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    lines = "\n".join(f"{k} = {v}" for k, v in entry_points.items())
    (info / "entry_points.txt").write_text(f"[motion_refiner.adapters]\n{lines}\n")
    for mod, src in (modules or {}).items():
        (root / f"{mod}.py").write_text(textwrap.dedent(src))


@pytest.fixture
def example_installed(tmp_path, monkeypatch):
    """The example plugin package visible to importlib.metadata, as ``pip install`` would make it."""
    monkeypatch.delenv(DISABLE_AUTOLOAD_ENV, raising=False)
    make_distribution(tmp_path, "motion-refiner-toymotion", {"toymotion": "toymotion_adapter"})
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLE))
    yield tmp_path
    sys.modules.pop("toymotion_adapter", None)


def test_builtins_registered_under_their_names(pm):
    assert set(BUILTIN_ADAPTERS) <= {name for name, _ in pm.list_name_plugin()}
    assert list(pm.adapters()) == sorted(BUILTIN_ADAPTERS)
    assert all(pm.sources[name] == "built-in" for name in BUILTIN_ADAPTERS)
    pm.check_pending()


@pytest.mark.parametrize("name", BUILTIN_ADAPTERS)
def test_builtin_adapter_info_is_valid(pm, name):
    info = pm.get_adapter(name)
    assert isinstance(info, AdapterInfo) and info.name == name
    assert set(info.skeletons) <= set(list_skeletons()) and info.skeletons[0] == "humanact12"
    assert info.fps == 20.0 and info.up in {"-y", "+y"} and len(info.format) > 20
    plugin = pm.get_plugin(name)
    assert plugin.__name__ == f"refiner.adapters.{name}"
    assert hasattr(plugin, "refiner_convert_output")


def test_hookspecs_are_documented_contracts():
    for name in HOOKS:
        spec = getattr(hookspecs, name)
        doc = " ".join(inspect.getdoc(spec).split())
        assert "Called by" in doc and "Returns" in doc, name
        first = getattr(spec, "motion_refiner_spec")["firstresult"]
        assert ("Stops at the first non-None result" in doc) == first, name
        if not first:
            assert "collected" in doc
    assert hookspecs.hookspec.project_name == hookimpl.project_name == "motion_refiner"


def test_get_adapter_unknown_name_lists_known(pm):
    with pytest.raises(ValueError, match=r"unknown adapter 'nope'; known adapters: action2motion, actor, mdm, mld"):
        pm.get_adapter("nope")
    with pytest.raises(ValueError, match="unknown adapter 'nope'"):
        get_adapter("nope", pm)
    with pytest.raises(ValueError, match="unknown adapter"):
        pm.convert("nope", np.zeros((2, 60, 72)))
    with pytest.raises(ValueError, match="cannot produce skeleton 'cmu_mocap'"):
        pm.convert("action2motion", np.zeros((2, 60, 72)), skeleton="cmu_mocap", options={"representation": "xyz"})
    assert [i.name for i in list_adapters(pm)] == sorted(BUILTIN_ADAPTERS)


def test_adapter_info_validation():
    ok = AdapterInfo("x_1", "fmt", ("humanact12",))
    assert ok.skeletons == ("humanact12",) and ok.fps == 20.0
    assert AdapterInfo("x", "fmt", "uestc").skeletons == ("uestc",)
    for kwargs, match in [
        (dict(name="Bad Name", format="f", skeletons=("humanact12",)), "lower-case identifier"),
        (dict(name="x", format=" ", skeletons=("humanact12",)), "format"),
        (dict(name="x", format="f", skeletons=()), "skeletons"),
        (dict(name="x", format="f", skeletons=("humanact12",), fps=0), "fps"),
        (dict(name="x", format="f", skeletons=("humanact12",), up="y"), "up"),
    ]:
        with pytest.raises(ValueError, match=match):
            AdapterInfo(**kwargs)


def test_entry_point_plugin_is_found_and_used(example_installed):
    from refiner import RefinedGenerator

    with warnings.catch_warnings():
        warnings.simplefilter("error", AdapterPluginWarning)  # built-ins listed as entry points too: no noise
        pm = get_plugin_manager()
    assert pm.sources["toymotion"] == "motion-refiner-toymotion 0.1.0"
    assert pm.get_adapter("toymotion").source == "motion-refiner-toymotion 0.1.0"
    assert set(BUILTIN_ADAPTERS) < set(pm.adapters())
    import toymotion_adapter

    generator = toymotion_adapter.ToyMotionGenerator()
    gen = RefinedGenerator(generator, refiner=lambda m: m, plugin_manager=pm)  # recognised, not named
    assert gen.adapter == "toymotion"
    motions, raw = gen.sample(2, n=3, return_raw=True, random_state=0)
    assert raw.shape == (3, 60, 24, 3) and len(motions) == 3
    for m, r in zip(motions, raw):
        expected = (r / 100.0) * np.array([1.0, -1.0, -1.0])
        np.testing.assert_allclose(m.joints, expected - expected[:1, :1], atol=1e-6)
        assert m.action == 2 and (m.joints[:, 15, 1] < m.joints[:, 0, 1]).all()  # y down
    # the default plugin manager of RefinedGenerator also sees it
    assert RefinedGenerator(generator, refiner=lambda m: m).adapter == "toymotion"


def test_autoload_switches(example_installed, monkeypatch):
    assert "toymotion" not in get_plugin_manager(autoload=False).adapters()
    monkeypatch.setenv(DISABLE_AUTOLOAD_ENV, "1")
    assert "toymotion" not in get_plugin_manager().adapters()
    monkeypatch.delenv(DISABLE_AUTOLOAD_ENV)
    assert "toymotion" in get_plugin_manager().adapters()


BROKEN_MODULES = {
    "mr_raising_adapter": """
        from refiner.plugins import hookimpl
        @hookimpl
        def refiner_adapter_info():
            raise RuntimeError("boom")
    """,
    "mr_typo_adapter": """
        from refiner.plugins import hookimpl
        @hookimpl
        def refiner_adaptor_info():
            return None
    """,
    "mr_badarg_adapter": """
        from refiner.plugins import hookimpl
        @hookimpl
        def refiner_convert_output(adapter, output, colour):
            return None
    """,
    "mr_duplicate_adapter": """
        from refiner.plugins import AdapterInfo, hookimpl
        @hookimpl
        def refiner_adapter_info():
            return AdapterInfo("actor", "a second 'actor'", ("humanact12",))
    """,
    "mr_noinfo_adapter": """
        from refiner.plugins import hookimpl
        @hookimpl
        def refiner_adapter_info():
            return {"name": "dict"}
    """,
    "mr_import_error_adapter": """
        raise ImportError("missing dependency xyz")
    """,
    "mr_bad_recognizer": """
        from refiner.plugins import hookimpl
        @hookimpl(tryfirst=True)
        def refiner_recognize_generator(generator):
            raise RuntimeError("cannot look at this")
    """,
}


def test_broken_plugins_warn_and_others_keep_working(example_installed, tmp_path, monkeypatch):
    """Each broken plugin is skipped with a warning naming it; the built-ins and the example still work."""
    broken_root = tmp_path / "broken"
    entry_points = {f"bad_{k}": k for k in BROKEN_MODULES}
    entry_points["bad_missing"] = "mr_no_such_module_anywhere"
    make_distribution(broken_root, "broken-plugins", entry_points, BROKEN_MODULES)
    monkeypatch.syspath_prepend(str(broken_root))
    try:
        with pytest.warns(AdapterPluginWarning) as record:
            pm = get_plugin_manager()
        messages = "\n".join(str(w.message) for w in record)
        for name, reason in [
            ("bad_mr_raising_adapter", "raised RuntimeError: boom"),
            ("bad_mr_typo_adapter", "'refiner_adaptor_info' is not a motion-refiner hook"),
            ("bad_mr_badarg_adapter", "could not be registered"),
            ("bad_mr_duplicate_adapter", "adapter name 'actor' is already taken by plugin 'actor' (built-in)"),
            ("bad_mr_noinfo_adapter", "must return an AdapterInfo"),
            ("bad_mr_import_error_adapter", "failed to import"),
            ("bad_missing", "failed to import"),
        ]:
            assert f"'{name}' (broken-plugins 0.1.0)" in messages and reason in messages, (name, reason)
        assert sorted(pm.adapters()) == sorted([*BUILTIN_ADAPTERS, "toymotion"])
        assert pm.get_plugin("bad_mr_raising_adapter") is None  # unregistered again
        assert pm.get_adapter("actor").source == "built-in"
        # the recogniser that raises is reported at call time and the next plugin answers
        import toymotion_adapter

        with pytest.warns(AdapterPluginWarning, match="bad_mr_bad_recognizer.*cannot look at this"):
            assert pm.adapter_for(toymotion_adapter.ToyMotionGenerator()) == "toymotion"
        motions = pm.convert("toymotion", toymotion_adapter.ToyMotionGenerator().sample(0, n=1))
        assert motions[0].joints.shape == (60, 24, 3)
    finally:
        for mod in BROKEN_MODULES:
            sys.modules.pop(mod, None)


def test_plugins_registered_by_hand(pm):
    class Plugin:
        @hookimpl
        def refiner_adapter_info(self):
            return AdapterInfo("handmade", "joints (T, 24, 3) metres", ("humanact12",))

        @hookimpl
        def refiner_convert_output(self, adapter, output):
            if adapter != "handmade":
                return None
            from refiner.core.motion import Motion

            return [Motion(output)]

    pm.register(Plugin(), name="handmade")
    assert pm.get_adapter("handmade").source == "registered"
    out = pm.convert("handmade", np.zeros((5, 24, 3)))
    assert out[0].n_frames == 5
    with pytest.raises(pluggy.PluginValidationError):
        class Bad:
            @hookimpl
            def refiner_recognize_generator(self, generator, extra):
                return None

        pm.register(Bad(), name="bad")


def test_adapters_command_lists_installed_adapters(capsys):
    from refiner.cli.main import main

    assert main(["adapters", "--no-autoload"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split()[:5] == ["adapter", "skeletons", "fps", "up", "from"]
    rows = {line.split()[0]: line.split() for line in out[1:]}
    assert set(rows) == set(BUILTIN_ADAPTERS)
    assert rows["motiondiffuse"][1:5] == ["humanact12,uestc", "20", "+y", "built-in"]
    assert "Lie VAE" in " ".join(rows["action2motion"])


def test_adapters_command_shows_where_plugins_come_from(example_installed, capsys):
    from refiner.cli.main import main

    assert main(["adapters"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.startswith("toymotion"))
    assert "motion-refiner-toymotion 0.1.0" in line and "centimetres" in line


def test_broken_builtin_is_skipped_with_a_warning(monkeypatch):
    import refiner.plugins.manager

    monkeypatch.setattr(refiner.plugins.manager, "BUILTIN_ADAPTERS", ("action2motion", "no_such_builtin"))
    with pytest.warns(AdapterPluginWarning, match="'no_such_builtin' \\(built-in\\) failed to import"):
        pm = get_plugin_manager(autoload=False)
    assert list(pm.adapters()) == ["action2motion"]


def test_import_refiner_stays_cheap():
    """`import refiner` must not import the adapters, the plugin manager or smplx."""
    import subprocess

    code = ("import sys, refiner; bad = [m for m in sys.modules if m.startswith(('refiner.adapters', "
            "'refiner.plugins', 'smplx', 'pluggy'))]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


def test_a_plugin_answering_for_every_name_cannot_take_over_a_builtin():
    """The manager calls the plugin registered under the requested adapter name, and only that one."""
    from refiner.core.motion import Motion

    pm = get_plugin_manager(autoload=False)

    class Greedy:
        @hookimpl(tryfirst=True)
        def refiner_adapter_info(self):
            return AdapterInfo("greedy", "anything", ("humanact12",))

        @hookimpl(tryfirst=True)
        def refiner_convert_output(self, adapter, output):  # no name filter: answers for everyone
            return [Motion(np.zeros((60, 24, 3)))]

        @hookimpl(tryfirst=True)
        def refiner_sample_generator(self, adapter, generator, action, n):
            return "hijacked"

    pm.register(Greedy(), name="greedy")
    raw = np.random.default_rng(0).normal(size=(1, 60, 72)).astype(np.float32) * 0.1
    out = pm.convert("action2motion", raw, options={"representation": "xyz"})
    assert np.abs(out[0].joints).max() > 0  # the built-in converted it, not the greedy plugin's zeros
    assert pm.convert("greedy", raw)[0].joints.max() == 0.0
    assert pm.sample("action2motion", object(), 0, 1, {}) != "hijacked"


def test_a_second_plugin_claiming_a_taken_name_is_refused_naming_both(pm):
    class Impostor:
        @hookimpl
        def refiner_adapter_info(self):
            return AdapterInfo("action2motion", "an impostor", ("humanact12",))

    with pytest.raises(ValueError, match="plugin 'impostor' claims adapter name 'action2motion'.*"
                                         "taken by plugin 'action2motion' \\(built-in\\)"):
        pm.register(Impostor(), name="impostor")
    assert pm.get_plugin("impostor") is None and pm.get_adapter("action2motion").source == "built-in"


def test_a_raising_convert_or_sample_hook_is_wrapped_naming_the_plugin(pm):
    from refiner.plugins.manager import AdapterPluginError
    from refiner.refinement.refined_generator import RefinedGenerator

    class Fragile:
        @hookimpl
        def refiner_adapter_info(self):
            return AdapterInfo("fragile", "joints", ("humanact12",))

        @hookimpl
        def refiner_convert_output(self, adapter, output):
            raise KeyError("joints3D")

        @hookimpl
        def refiner_sample_generator(self, adapter, generator, action, n):
            raise RuntimeError("out of memory")

    pm.register(Fragile(), name="fragile_plugin")
    with pytest.raises(AdapterPluginError, match="adapter 'fragile' \\(plugin 'fragile_plugin', registered\\): "
                                                 "refiner_convert_output failed: KeyError: 'joints3D'") as info:
        pm.convert("fragile", np.zeros((5, 24, 3)))
    assert info.value.plugin == "fragile_plugin" and isinstance(info.value.__cause__, KeyError)
    gen = RefinedGenerator(lambda action, n: None, adapter="fragile", refiner=lambda m: m, plugin_manager=pm)
    with pytest.raises(AdapterPluginError, match="'fragile_plugin'.*refiner_sample_generator failed: RuntimeError: "
                                                 "out of memory"):
        gen.sample(0)
    with pytest.raises(ValueError, match="plugin 'action2motion', built-in.*representation"):  # built-ins too
        pm.convert("action2motion", np.zeros((1, 60, 72)))


def test_builtin_adapters_do_not_filter_by_adapter_name(pm):
    """The manager calls only the plugin that registered the adapter, so built-ins take no `adapter` argument."""
    for name in BUILTIN_ADAPTERS:
        plugin = pm.get_plugin(name)
        for hook in ("refiner_convert_output", "refiner_sample_generator", "refiner_encode_motions",
                     "refiner_read_file", "refiner_write_refined"):
            impl = getattr(plugin, hook, None)
            assert impl is None or "adapter" not in inspect.signature(impl).parameters, (name, hook)


def test_file_hooks_are_optional_and_wrapped(pm, tmp_path):
    """An adapter without its own file format reads and writes none (None); one whose reader raises is named."""
    from refiner.plugins.manager import AdapterPluginError

    assert pm.read_file("action2motion", tmp_path / "x.npy") is None
    assert pm.write_refined("action2motion", tmp_path / "x.npy", None, [], []) is None and not any(tmp_path.iterdir())

    class Picky:
        @hookimpl
        def refiner_adapter_info(self):
            return AdapterInfo("picky", "joints", ("humanact12",))

        @hookimpl
        def refiner_read_file(self, path):
            raise ValueError(f"{path.name} is not picky")

    pm.register(Picky(), name="picky_plugin")
    with pytest.raises(AdapterPluginError, match="'picky_plugin'.*refiner_read_file failed: x.npy is not picky"):
        pm.read_file("picky", tmp_path / "x.npy")


def test_encode_calls_the_owner_and_checks_what_it_gets(pm):
    from refiner.core.motion import Motion
    from refiner.plugins.manager import encode

    motion = Motion(np.random.default_rng(0).normal(size=(8, 24, 3)) * 0.1)
    (xyz,) = pm.encode("action2motion", [motion], options={"representation": "xyz"})
    assert xyz.shape == (8, 72) and xyz.dtype == np.float32
    back = pm.convert("action2motion", xyz[None], options={"representation": "xyz"})[0]
    np.testing.assert_array_equal(back.joints, motion.joints)
    assert encode("action2motion", motion, pm=pm, representation="lie")[0].shape == (8, 72)
    with pytest.raises(ValueError, match="'actor' .*does not implement refiner_encode_motions"):
        pm.encode("actor", [motion])
    with pytest.raises(ValueError, match="cannot encode skeleton"):
        pm.encode("action2motion", [Motion(np.zeros((8, 22, 3)), skeleton="humanml3d")])
    with pytest.raises(ValueError, match="must be Motion objects"):
        pm.encode("action2motion", [np.zeros((8, 24, 3))])
    with pytest.raises(ValueError, match="unknown option.*'colour'.*accepted: representation, continuous"):
        pm.encode("action2motion", [motion], options={"colour": 1})


def test_old_import_paths_warn_and_give_the_same_objects():
    import refiner.adapters
    import refiner.adapters.base
    import refiner.core.rotations
    import refiner.plugins

    with pytest.warns(DeprecationWarning, match="refiner.plugins.adapter_info.AdapterInfo"):
        from refiner.adapters.base import AdapterInfo as old
    assert old is AdapterInfo
    with pytest.warns(DeprecationWarning, match="refiner.core.rotations"):
        assert refiner.adapters.base.rotvec_to_rotmat is refiner.core.rotations.rotvec_to_rotmat
    with pytest.warns(DeprecationWarning, match="refiner.plugins.BUILTIN_ADAPTERS"):
        assert refiner.adapters.BUILTIN_ADAPTERS == refiner.plugins.BUILTIN_ADAPTERS
    with pytest.raises(AttributeError):
        refiner.adapters.base.no_such_name


def test_recognize_is_the_deprecated_name_of_adapter_for(pm):
    with pytest.warns(DeprecationWarning, match="adapter_for"):
        assert pm.recognize(object()) is None
