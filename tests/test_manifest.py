"""Weights manifests: schema errors are clear ValueErrors, and the content hash catches edited names or thresholds."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from refiner.core.manifest import CONTENT_KEY, content_sha256, read_generator_manifest, read_refiner_manifest, write_manifest
from refiner.reference import GENERATOR_KINDS, WEIGHTS_DIR, load_reference_generator
from refiner.refinement.pipeline import _PARTS, _WEIGHTS, Refiner


@pytest.fixture()
def weights_copy(tmp_path):
    """A copy of the shipped train-split refiner weights, to edit."""
    folder = tmp_path / "weights"
    shutil.copytree(_WEIGHTS / "humanact12-train", folder)
    return folder


def edit(folder: Path, change, *, rehash: bool = False):
    """Apply ``change`` to the manifest in ``folder``; ``rehash`` re-signs it (a schema error, not a hash one)."""
    path = folder / "manifest.json"
    manifest = json.loads(path.read_text())
    change(manifest)
    if rehash:
        write_manifest(path, manifest)
    else:
        path.write_text(json.dumps(manifest, indent=2))


@pytest.mark.parametrize("folder", ["humanact12", "humanact12-train"])
def test_shipped_refiner_manifests_carry_their_content_hash(folder):
    manifest, paths = read_refiner_manifest(_WEIGHTS / folder, _PARTS)
    assert manifest[CONTENT_KEY] == content_sha256(manifest)
    assert set(paths) == set(_PARTS) and len(manifest["action_names"]) == 12  # the concepts method's parts
    assert sorted(p.name for p in (_WEIGHTS / folder).glob("*.safetensors")) == sorted(p.name for p in paths.values())
    refiner = Refiner.load(_WEIGHTS / folder)
    assert refiner.method == "concepts" and refiner.anchor_quality.threshold_ == pytest.approx(
        manifest["calibration"]["anchor_threshold"])


def test_shipped_generator_manifest_carries_its_content_hash():
    manifest, paths = read_generator_manifest(WEIGHTS_DIR)
    assert manifest[CONTENT_KEY] == content_sha256(manifest) and set(paths) == set(GENERATOR_KINDS)


def test_shipped_weights_stay_under_30_mb_in_all():
    """Issue budget: every shipped file under ``refiner/weights`` (refiners, generators, evaluators) together."""
    total = sum(p.stat().st_size for p in _WEIGHTS.rglob("*") if p.is_file())
    assert total < 30e6, f"{total / 1e6:.2f} MB"


@pytest.mark.parametrize("change", [
    lambda m: m["action_names"].reverse(),
    lambda m: m["calibration"].__setitem__("anchor_threshold", m["calibration"]["anchor_threshold"] + 1.0),
    lambda m: m.__setitem__("licence", "free for all uses"),
    lambda m: m.pop(CONTENT_KEY),
], ids=["reversed-action-names", "anchor-threshold", "licence", "hash-removed"])
def test_edited_manifest_content_is_refused(weights_copy, change):
    edit(weights_copy, change)
    with pytest.raises(ValueError, match=f"does not match its `{CONTENT_KEY}`"):
        Refiner.load(weights_copy)
    Refiner.load(weights_copy, verify=False)  # the schema is still valid: only the hash check refuses it


@pytest.mark.parametrize("change, match", [
    (lambda m: m.pop("files"), "has no `files` entry"),
    (lambda m: m.__setitem__("action_names", "warm_up walk"), "`action_names` must be a list"),
    (lambda m: m.__setitem__("action_names", ["walk"] * 12), "distinct strings"),
    (lambda m: m.__setitem__("skeleton", 24), "`skeleton` must be a str"),
    (lambda m: m["files"]["recognizer"].pop("sha256"), r"`files.recognizer` must be"),
    (lambda m: m["files"].__setitem__("extra", {"file": "x", "sha256": "0" * 64}), "unknown part 'extra'"),
    (lambda m: m["files"]["recognizer"].__setitem__("file", "../../etc/passwd"), "must be a file name"),
    (lambda m: m["calibration"].__setitem__("anchor_threshold", "high"), "`calibration.anchor_threshold` must be"),
    (lambda m: m["calibration"].__setitem__("transition_thresholds", [[8.0]]), "transition_thresholds"),
])
def test_manifest_schema_errors_are_value_errors(weights_copy, change, match):
    edit(weights_copy, change, rehash=True)
    with pytest.raises(ValueError, match=match):
        Refiner.load(weights_copy)


def test_deleted_weight_file_and_bad_json(weights_copy):
    (weights_copy / "anchor_refiner.safetensors").unlink()
    with pytest.raises(ValueError, match=r"anchor_refiner.safetensors' is listed in .* but missing"):
        Refiner.load(weights_copy)
    (weights_copy / "manifest.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        Refiner.load(weights_copy)


def test_generator_manifest_edits_and_schema(tmp_path):
    folder = tmp_path / "generators"
    shutil.copytree(WEIGHTS_DIR, folder)
    edit(folder, lambda m: m["generators"]["a2m"]["adapter_options"].__setitem__("representation", "xyz"))
    with pytest.raises(ValueError, match="does not match its"):
        load_reference_generator("a2m", folder=folder)
    edit(folder, lambda m: m.pop("generators"), rehash=True)
    with pytest.raises(ValueError, match="has no `generators` entry"):
        load_reference_generator("a2m", folder=folder)
