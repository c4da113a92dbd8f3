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
