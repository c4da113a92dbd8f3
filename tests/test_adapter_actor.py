"""ACTOR adapter: rot6d conventions and the SMPL path, on a stand-in SMPL model file of the real structure."""
from __future__ import annotations

import os
import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse
from scipy.spatial.transform import Rotation

from refiner.adapters import actor
from refiner.adapters.action2motion import lie_to_joints
from refiner.core.rotations import rot6d_to_rotmat, rotmat_to_rot6d

SMPL_PARENTS = np.array([-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21])
N_VERTS = 6890  # smplx picks keypoints up to vertex 6787, so the stand-in keeps SMPL's vertex count


def write_standin_smpl(folder, seed=0):
    """Write ``SMPL_NEUTRAL.pkl`` and ``J_regressor_extra.npy``: random but structurally valid SMPL arrays.

    The arrays are :func:`standin_smpl_arrays`; the regressor rows are random sparse-ish weights.
    """
    rng = np.random.default_rng(seed + 1)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "SMPL_NEUTRAL.pkl", "wb") as fh:
        pickle.dump(standin_smpl_arrays(seed), fh, protocol=2)
    extra = rng.random((9, N_VERTS)) ** 8
    np.save(folder / "J_regressor_extra.npy", (extra / extra.sum(1, keepdims=True)).astype(np.float32))
    return folder


def standin_smpl_arrays(seed=0):
    """The arrays of an SMPL neutral model: random but structurally valid.

    Same keys, shapes and conventions as the real neutral model (checked against smplx's
    ``SMPL.__init__``): v_template (V, 3), shapedirs (V, 3, 10), posedirs (V, 3, 207), J_regressor
    (24, V), weights (V, 24), kintree_table (2, 24), f (F, 3). The rest joints are a body-like tree
    (J_regressor picks vertices 0..23 placed there).
    """
    rng = np.random.default_rng(seed)
    rest = np.asarray(lie_to_joints(np.zeros((1, 72)), recenter=False)[0], dtype=np.float64)
    rest = rest * np.array([1.0, -1.0, -1.0])  # upright in SMPL's y-up model frame
    v_template = rest[rng.integers(0, 24, N_VERTS)] + rng.normal(scale=0.05, size=(N_VERTS, 3))
    v_template[:24] = rest
    j_regressor = np.zeros((24, N_VERTS))
    j_regressor[np.arange(24), np.arange(24)] = 1.0
    weights = rng.random((N_VERTS, 24)) ** 4
    weights /= weights.sum(1, keepdims=True)
    kintree = np.stack([SMPL_PARENTS, np.arange(24)]).astype(np.int64)
    kintree[0, 0] = 4294967295  # as in the real file
    model = {
        "v_template": v_template.astype(np.float32),
        "shapedirs": (rng.normal(size=(N_VERTS, 3, 10)) * 0.01).astype(np.float32),
        "posedirs": (rng.normal(size=(N_VERTS, 3, 207)) * 0.001).astype(np.float32),
        "J_regressor": j_regressor.astype(np.float32),
        "weights": weights.astype(np.float32),
        "kintree_table": kintree,
        "f": rng.integers(0, N_VERTS, size=(13776, 3)).astype(np.int64),
    }
    return model


@pytest.fixture(scope="session")
def smpl_dir(tmp_path_factory):
    return write_standin_smpl(tmp_path_factory.mktemp("smpl"))


def expected_smpl_joints(rotmats, rest):
    """Reference LBS skeleton joints: posed_j = posed_parent + G_parent (rest_j - rest_parent), G_j = G_parent R_j."""
    n = len(rotmats)
    glob = np.zeros((n, 24, 3, 3))
    posed = np.zeros((n, 24, 3))
    glob[:, 0] = rotmats[:, 0]
    posed[:, 0] = rest[0]
    for j in range(1, 24):
        p = SMPL_PARENTS[j]
        glob[:, j] = glob[:, p] @ rotmats[:, j]
        posed[:, j] = posed[:, p] + np.einsum("nij,j->ni", glob[:, p], rest[j] - rest[p])
    return posed


def random_actor_output(rng, batch=2, frames=12, trans_scale=0.3):
    rot = Rotation.random(batch * frames * 24, random_state=int(rng.integers(1 << 30))).as_matrix()
    rot = rot.reshape(batch, frames, 24, 3, 3)
    out = np.zeros((batch, 25, 6, frames), dtype=np.float32)
    out[:, :24] = rotmat_to_rot6d(rot).transpose(0, 2, 3, 1)
    out[:, 24, :3] = (rng.normal(size=(batch, frames, 3)) * trans_scale).transpose(0, 2, 1)
    return out, rot


def test_rot6d_round_trip_and_row_convention(rng):
    rot = Rotation.random(500, random_state=1).as_matrix()
    d6 = rotmat_to_rot6d(rot)
    np.testing.assert_array_equal(d6, rot[:, :2, :].reshape(500, 6))  # first two ROWS (pytorch3d)
    np.testing.assert_allclose(rot6d_to_rotmat(d6), rot, atol=1e-12)
    # any non-degenerate 6D input decodes to a proper rotation; scaling the rows does not matter
    noisy = rot6d_to_rotmat(d6 * 3.0 + rng.normal(scale=0.05, size=d6.shape))
    np.testing.assert_allclose(noisy @ np.swapaxes(noisy, 1, 2), np.broadcast_to(np.eye(3), noisy.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(noisy), 1.0, atol=1e-12)
    np.testing.assert_allclose(rot6d_to_rotmat(d6 * 3.0), rot, atol=1e-12)
    with pytest.raises(ValueError, match="degenerate"):
        rot6d_to_rotmat(np.zeros((2, 6)))


def test_smpl_joints_match_lbs_skeleton_with_translation(smpl_dir, rng):
    """jointstype 'smpl', vertstrans=True: LBS joints, root pinned per frame, plus translation minus frame 0."""
    out, rot = random_actor_output(rng)
    before = out.copy()
    clips = actor.rot6d_to_joints(out, smpl_path=smpl_dir)
    np.testing.assert_array_equal(out, before)
    rest = np.asarray(actor.load_smpl(smpl_dir).v_template[:24].double().numpy())
    for b, clip in enumerate(clips):
        ref = expected_smpl_joints(rot[b], rest)
        trans = out[b, 24, :3].T.astype(np.float64)
        ref = ref - ref[:, :1] + (trans - trans[:1])[:, None]
        assert clip.shape == (12, 24, 3)
        np.testing.assert_allclose(clip, ref, atol=2e-5)
        np.testing.assert_allclose(clip[0, 0], 0.0, atol=1e-6)
    no_trans = actor.rot6d_to_joints(out, smpl_path=smpl_dir, vertstrans=False)
    np.testing.assert_allclose(no_trans[0][:, 0], 0.0, atol=1e-6)  # root pinned every frame


def test_column_convention_would_give_other_joints(smpl_dir, rng):
    """Guards the ROW convention: transposed rotations give clearly different joints."""
    out, rot = random_actor_output(rng, batch=1)
    transposed = out.copy()
    transposed[:, :24] = rotmat_to_rot6d(np.swapaxes(rot, -1, -2)).transpose(0, 2, 3, 1)
    a = actor.rot6d_to_joints(out, smpl_path=smpl_dir)[0]
    b = actor.rot6d_to_joints(transposed, smpl_path=smpl_dir)[0]
    assert np.abs(a - b).max() > 0.1


def test_mask_drops_padded_frames_and_dict_input(smpl_dir, rng):
    out, _ = random_actor_output(rng, batch=2, frames=10)
    out[1, :, :, 6:] = 0.0  # ACTOR zeroes padded frames
    mask = np.zeros((2, 10), dtype=bool)
    mask[0] = True
    mask[1, :6] = True
    motions = actor.to_motions({"output": out, "mask": mask, "y": np.array([3, 7]), "lengths": np.array([10, 6])},
                               smpl_path=smpl_dir)
    assert [m.n_frames for m in motions] == [10, 6] and [m.action for m in motions] == [3, 7]
    full = actor.rot6d_to_joints(out[:1], smpl_path=smpl_dir)[0]
    np.testing.assert_allclose(motions[0].joints, full, atol=1e-6)
    with pytest.raises(ValueError, match="degenerate"):
        actor.rot6d_to_joints(out, smpl_path=smpl_dir)  # without the mask the zero frames are decoded


def test_uestc_a2m_layout(smpl_dir, rng):
    """The 18 'a2m' joints: 14 SMPL joints, nose / heels = vertices 332 / 3387 / 6787, head top = extra row 3."""
    import torch

    out, rot = random_actor_output(rng, batch=1, frames=5)
    a2m = actor.rot6d_to_joints(out, smpl_path=smpl_dir, skeleton="uestc", vertstrans=False)[0]
    smpl = actor.rot6d_to_joints(out, smpl_path=smpl_dir, vertstrans=False)[0]
    assert a2m.shape == (5, 18, 3)
    np.testing.assert_allclose(a2m[:, [0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 13, 14]],
                               smpl[:, [0, 12, 17, 19, 21, 16, 18, 20, 2, 5, 8, 1, 4, 7]], atol=1e-5)
    layer = actor.load_smpl(smpl_dir)
    r = torch.as_tensor(rot[0], dtype=torch.float32)
    with torch.no_grad():
        res = layer(global_orient=r[:, :1], body_pose=r[:, 1:])
    verts = res.vertices.double().numpy()
    root = res.joints[:, :1].double().numpy()
    extra = np.load(smpl_dir / "J_regressor_extra.npy").astype(np.float64)
    np.testing.assert_allclose(a2m[:, 8], verts[:, 332] - root[:, 0], atol=1e-5)
    np.testing.assert_allclose(a2m[:, 15], verts[:, 3387] - root[:, 0], atol=1e-5)
    np.testing.assert_allclose(a2m[:, 16], verts[:, 6787] - root[:, 0], atol=1e-5)
    np.testing.assert_allclose(a2m[:, 17], extra[3] @ verts - root[:, 0], atol=1e-5)


def test_missing_smpl_and_regressor_files(tmp_path, monkeypatch, smpl_dir, rng):
    monkeypatch.delenv(actor.SMPL_ENV, raising=False)
    monkeypatch.delenv(actor.J_REGRESSOR_EXTRA_ENV, raising=False)
    out, _ = random_actor_output(rng, batch=1, frames=4)
    with pytest.raises(ValueError, match=r"smpl_path=.*MOTION_REFINER_SMPL"):
        actor.rot6d_to_joints(out)
    with pytest.raises(ValueError, match="not a file"):
        actor.rot6d_to_joints(out, smpl_path=tmp_path / "nowhere.pkl")
    with pytest.raises(ValueError, match="not a file"):  # a folder without SMPL_NEUTRAL.pkl
        actor.rot6d_to_joints(out, smpl_path=tmp_path)
    (tmp_path / "bad.pkl").write_bytes(b"not a pickle")
    with pytest.raises(ValueError, match="not a usable SMPL model file"):
        actor.rot6d_to_joints(out, smpl_path=tmp_path / "bad.pkl")
    monkeypatch.setenv(actor.SMPL_ENV, str(smpl_dir / "SMPL_NEUTRAL.pkl"))
    assert actor.rot6d_to_joints(out)[0].shape == (4, 24, 3)  # found through the env var
    lone = tmp_path / "lone"
    lone.mkdir()
    (lone / "SMPL_NEUTRAL.pkl").write_bytes((smpl_dir / "SMPL_NEUTRAL.pkl").read_bytes())
    with pytest.raises(ValueError, match=r"j_regressor_extra=.*MOTION_REFINER_J_REGRESSOR_EXTRA"):
        actor.rot6d_to_joints(out, smpl_path=lone, skeleton="uestc")
    with pytest.raises(ValueError, match=r"\(9, 6890\)"):
        actor.rot6d_to_joints(out, smpl_path=lone, skeleton="uestc", j_regressor_extra=np.zeros((4, 6890)))


class _WritesFile:
    """Unpickling this calls ``os.system``: what a crafted SMPL file does."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_crafted_smpl_pickle_runs_nothing(tmp_path, rng):
    """A .pkl whose unpickling would run a shell command is refused before anything is called."""
    marker = tmp_path / "pwned"
    model = standin_smpl_arrays()
    model["v_template"] = _WritesFile(marker)
    (tmp_path / "SMPL_NEUTRAL.pkl").write_bytes(pickle.dumps(model, protocol=2))
    out, _ = random_actor_output(rng, batch=1, frames=4)
    with pytest.raises(ValueError, match=r"not a usable SMPL model file: it names posix\.system"):
        actor.rot6d_to_joints(out, smpl_path=tmp_path)
    assert not marker.exists()


def test_smpl_pickle_of_chumpy_and_sparse_arrays_loads_without_chumpy(tmp_path, smpl_dir, rng, monkeypatch):
    """Original SMPL files: chumpy ``Ch`` objects (values in state 'x') and a sparse J_regressor."""
    chumpy_ch = types.ModuleType("chumpy.ch")

    class Ch:  # pickles as chumpy.ch.Ch with its __dict__ as state, as chumpy does
        def __init__(self, x):
            self.x, self._dirty_vars = x, set()

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    chumpy_ch.Ch = Ch
    monkeypatch.setitem(sys.modules, "chumpy", types.ModuleType("chumpy"))
    monkeypatch.setitem(sys.modules, "chumpy.ch", chumpy_ch)
    model = standin_smpl_arrays()
    for key in ("v_template", "shapedirs", "posedirs", "weights"):
        model[key] = Ch(model[key])
    model["J_regressor"] = scipy.sparse.csc_matrix(model["J_regressor"])
    (tmp_path / "SMPL_NEUTRAL.pkl").write_bytes(pickle.dumps(model, protocol=2))
    monkeypatch.delitem(sys.modules, "chumpy.ch")
    monkeypatch.delitem(sys.modules, "chumpy")
    out, _ = random_actor_output(rng, batch=1, frames=4)
    got = actor.rot6d_to_joints(out, smpl_path=tmp_path)[0]
    np.testing.assert_allclose(got, actor.rot6d_to_joints(out, smpl_path=smpl_dir)[0], atol=1e-6)
    assert "chumpy" not in sys.modules
    np.savez(tmp_path / "model.npz", **standin_smpl_arrays())  # the pickle-free format
    np.testing.assert_allclose(actor.rot6d_to_joints(out, smpl_path=tmp_path / "model.npz")[0], got, atol=1e-6)


def test_wrong_shapes_and_masks(smpl_dir):
    with pytest.raises(ValueError, match=r"\(B, 25, 6, T\)"):
        actor.rot6d_to_joints(np.zeros((2, 25, 3, 10)), smpl_path=smpl_dir)
    with pytest.raises(ValueError, match="prefix"):
        actor.rot6d_to_joints(np.ones((1, 25, 6, 4)), np.array([[True, False, True, True]]), smpl_path=smpl_dir)
    with pytest.raises(ValueError, match="`mask` must have shape"):
        actor.rot6d_to_joints(np.ones((1, 25, 6, 4)), np.ones((2, 4), bool), smpl_path=smpl_dir)
    with pytest.raises(ValueError, match="skeleton"):
        actor.rot6d_to_joints(np.ones((1, 25, 6, 4)), smpl_path=smpl_dir, skeleton="humanml3d")
    with pytest.raises(ValueError, match="must hold 'output'"):
        actor.to_motions({"x": 1}, smpl_path=smpl_dir)


class FakeActorModel:
    """Duck-types ACTOR's CAE: ``generate(classes, durations)`` returning the batch dict, SMPL settings."""

    param2xyz = {"jointstype": "smpl", "vertstrans": False}
    rotation2xyz = None

    def __init__(self, seed=0):
        self.rng = np.random.default_rng(seed)
        self.calls = []

    def generate(self, classes, durations, nspa=1):
        import torch

        self.calls.append((classes.tolist(), durations.tolist()))
        out, _ = random_actor_output(self.rng, batch=len(classes), frames=int(durations.max()))
        return {"output": torch.from_numpy(out), "mask": torch.ones(len(classes), int(durations.max()), dtype=torch.bool),
                "y": classes, "lengths": durations}


def test_actor_model_is_recognised_and_sampled(smpl_dir, pm):
    from refiner import RefinedGenerator

    model = FakeActorModel()
    assert pm.adapter_for(model) == "actor"
    assert pm.adapter_for(object()) is None
    shift = np.array([0.0, 0.0, 0.5], dtype=np.float32)
    gen = RefinedGenerator(model, refiner=lambda m: m.with_joints(m.joints + shift),
                           adapter_options={"smpl_path": smpl_dir}, plugin_manager=pm)
    assert gen.adapter == "actor" and gen.skeleton == "humanact12"
    motions, raw = gen.sample(4, n=2, return_raw=True, n_frames=8)
    assert model.calls == [([4, 4], [8, 8])]
    unrefined = pm.convert("actor", raw, options={"smpl_path": smpl_dir})
    for m, u in zip(motions, unrefined):
        assert m.action == 4 and m.n_frames == 8
        np.testing.assert_allclose(m.joints - u.joints, np.broadcast_to(shift, m.joints.shape), atol=1e-6)
    with pytest.raises(ValueError, match="integer action"):
        gen.sample("walk")
