"""The package layout the README draws: sub-packages by concept, one-way imports, small modules."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SUBPACKAGES = ("core", "nn", "concepts", "refinement", "evaluation", "reference", "io", "corpus", "cli")
#: What each sub-package of ``refiner`` may import from the others (besides itself); the README's arrows.
ALLOWED = {
    "core": set(),
    "nn": {"core"},
    "io": {"core"},
    "concepts": {"core", "nn", "io"},
    "refinement": {"core", "nn", "concepts", "io", "plugins"},
    "reference": {"core", "nn", "io", "plugins"},
    "evaluation": {"core", "nn", "concepts", "io", "refinement", "reference", "plugins"},
    "corpus": {"core", "nn", "refinement", "plugins", "cli"},  # cli: its file loader, the one refine uses
    "cli": set(SUBPACKAGES) | {"plugins"},
    "plugins": {"core"},
    "adapters": {"core", "plugins"},
}
LAYERS = SUBPACKAGES + ("plugins", "adapters")
ADAPTER_MODULES = {p.stem for p in (REPO / "adapters").glob("*.py")} - {"__init__"}


def _modules(folder: str):
    return sorted((REPO / folder).rglob("*.py"))


def _imports(path: Path) -> list[str]:
    """Every module named by an import anywhere in ``path`` (function-level imports too)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append(node.module)
            out += [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            out += [a.name for a in node.names]
    return out


def _length(path: Path) -> int:
    return len(path.read_text().splitlines())


def test_no_module_over_400_lines():
    long = {str(p.relative_to(REPO)): _length(p) for f in ("refiner", "adapters", "plugins") for p in _modules(f)
            if _length(p) > 400}
    assert not long, long


def test_every_refiner_module_sits_in_a_subpackage():
    loose = {p.name for p in (REPO / "refiner").glob("*.py")} - {"__init__.py", "__main__.py"}
    assert not loose, loose
    assert {p.name for p in (REPO / "refiner").iterdir() if p.is_dir() and (p / "__init__.py").is_file()} == set(SUBPACKAGES)


def _layer(module: str) -> str | None:
    """The layer an imported module belongs to (``adapters.x`` and ``plugins.x`` are the installed names too)."""
    parts = module.split(".")
    if parts[0] in ("adapters", "plugins"):
        return parts[0]
    return parts[1] if parts[0] == "refiner" and len(parts) > 1 and parts[1] in LAYERS else None


@pytest.mark.parametrize("layer", LAYERS)
def test_imports_follow_the_arrows(layer):
    folder = layer if layer in ("plugins", "adapters") else f"refiner/{layer}"
    bad = [f"{path.relative_to(REPO)} imports {name}" for path in _modules(folder) for name in _imports(path)
           if _layer(name) not in (None, layer) and _layer(name) not in ALLOWED[layer]]
    assert not bad, bad


def test_the_contract_does_not_import_the_adapters():
    bad = [f"{p.relative_to(REPO)}: {n}" for p in _modules("plugins") for n in _imports(p)
           if n.split(".")[0] == "adapters" or n.startswith("refiner.adapters")]
    assert not bad, bad


def test_only_adapters_import_adapter_modules():
    bad = []
    for folder in ("refiner", "plugins", "examples"):
        for p in _modules(folder):
            for n in _imports(p):
                parts = n.split(".")
                if parts[:2] == ["refiner", "adapters"] and len(parts) > 2 and parts[2] in ADAPTER_MODULES:
                    bad.append(f"{p.relative_to(REPO)}: {n}")
                elif parts[0] == "adapters" and len(parts) > 1 and parts[1] in ADAPTER_MODULES:
                    bad.append(f"{p.relative_to(REPO)}: {n}")
    assert not bad, bad


def test_old_flat_import_paths_are_gone():
    """0.1's flat paths (``refiner.pipeline``) were deprecated aliases of a release never published; they are removed."""
    import importlib

    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("refiner.pipeline")
