import importlib.resources
import subprocess
import sys

import refiner


def test_public_api_and_version():
    assert refiner.__version__ != "unknown"
    for name in refiner.__all__:
        assert hasattr(refiner, name), name


def test_mapped_subpackages_import():
    import refiner.adapters
    import refiner.plugins

    assert refiner.adapters.__name__ == "refiner.adapters"
    assert refiner.plugins.__name__ == "refiner.plugins"


def test_weights_folder_is_package_data():
    assert (importlib.resources.files("refiner") / "weights").is_dir()


def test_console_script_runs():
    out = subprocess.run([sys.executable, "-m", "refiner", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "concepts" in out.stdout


def test_wheel_contains_the_weights(tmp_path):
    """A built wheel ships every weights folder (package-data), not only editable installs."""
    import zipfile

    repo = importlib.resources.files("refiner").joinpath("..")
    out = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                          "-w", str(tmp_path), str(repo)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    names = zipfile.ZipFile(next(tmp_path.glob("*.whl"))).namelist()
    for folder in ("humanact12-motion", "humanact12", "humanact12-train", "generators", "evaluators"):
        assert any(n.startswith(f"refiner/weights/{folder}/") and n.endswith(".safetensors") for n in names), folder
        assert f"refiner/weights/{folder}/manifest.json" in names
    for module in ("motion_refiner", "motion_model", "networks/motion_net", "steps/infill", "steps/base"):  # the default
        assert f"refiner/refinement/{module}.py" in names, module
    assert "refiner/weights/evaluators/LICENSE-action-to-motion.txt" in names  # MIT: the licence travels along
