"""Bad input gives clear errors naming the file and field (issue 12, group 3): skills,
demonstrations, PCAE weights; and the learned reward stays finite and does not
reward what the goal model cannot explain (group 1)."""

import json
import shutil

import numpy as np
import pytest

from drake_skill.action.dmp import DmpConfig, fit_demonstrations
from drake_skill.fileio import atomic_save_npz, file_sha256, load_npz
from drake_skill.perception.features import GoalFeatures
from drake_skill.perception.pcae import default_weights
from drake_skill.reward.goal_model import GoalModelConfig
from drake_skill.reward.pomrp import PomrpConfig, fit_pomrp
from drake_skill.fitted_skill import Skill, SkillConfig


# ----------------------------------------------------------------- a small skill
def _trajectory(seed: int, n: int = 51):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 5.0, n)
    s = t / 5.0
    poses = np.zeros((n, 7))
    poses[:, 0] = (0.3 + 0.02 * rng.standard_normal()) * (10 * s**3 - 15 * s**4 + 6 * s**5)
    poses[:, 2] = 0.2 + 0.1 * np.sin(np.pi * s) ** 2
    poses[:, 3] = 1.0
    return t, poses


def _codes(seed: int, n: int = 51):
    """128-D codes moving through three sub-goals (a stand-in for PCAE codes)."""
    rng = np.random.default_rng(seed)
    goals = np.random.default_rng(99).normal(size=(3, 128))
    stage = np.minimum((np.linspace(0.0, 3.0, n, endpoint=False)).astype(int), 2)
    return goals[stage] + 0.05 * rng.standard_normal((n, 128))


def synthetic_skill(seed: int = 0) -> Skill:
    """A complete Skill from synthetic data (no simulation): 2 demonstrations, B = 10."""
    config = SkillConfig(skill="open", dmp=DmpConfig(n_basis=10), seed=seed,
                         pomrp=PomrpConfig(goal_model=GoalModelConfig(
                             n_states_min=2, n_states_max=3, covariance_types=["diag"], n_restarts=1)))
    fit = fit_demonstrations([_trajectory(seed), _trajectory(seed + 1)], config.dmp, seed=seed)
    codes = [_codes(seed), _codes(seed + 1)]
    lengths = np.array([len(c) for c in codes])
    pca = GoalFeatures(8).fit(np.concatenate(codes), lengths)
    goal = [pca.transform(c) for c in codes]
    pomrp = fit_pomrp(np.concatenate(goal), lengths, config.pomrp)
    info = {"pca_explained_variance": float(pca.total_explained_variance_ratio),
            "demo_lengths": lengths.tolist(), "demo_returns": [pomrp.episode_return(G) for G in goal],
            "demo_verdicts": [pomrp.verdict(G) for G in goal], "seed": seed}
    return Skill(config, fit.dmps, fit.initial_index, fit.sigma0, pca, pomrp, default_weights(), info,
                 gripper_opening=0.08)


@pytest.fixture(scope="module")
def saved_skill(tmp_path_factory):
    directory = tmp_path_factory.mktemp("skill") / "open"
    synthetic_skill(0).save(directory)
    return directory


def _copy(saved_skill, tmp_path):
    out = tmp_path / "skill"
    shutil.copytree(saved_skill, out)
    return out


def _rewrite_arrays(directory, **changes):
    """Edits arrays.npz and updates its checksum, as a writer of a bad model would."""
    arrays = load_npz(directory / "arrays.npz")
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    atomic_save_npz(directory / "arrays.npz", arrays)
    _reseal(directory, "arrays.npz")


def _reseal(directory, name):
    from drake_skill.fileio import file_sha256

    meta = json.loads((directory / "skill.json").read_text())
    meta["sha256"][name] = file_sha256(directory / name)
    (directory / "skill.json").write_text(json.dumps(meta))


def test_saved_skill_loads_back(saved_skill):
    skill = Skill.load(saved_skill)
    assert skill.name == "open" and len(skill.dmps) == 2 and skill.sigma0.shape == (10, 7, 7)
    assert skill.pomrp.off_model_config.enabled and skill.pomrp.frame_loglik_range is not None
    meta = json.loads((saved_skill / "skill.json").read_text())
    assert set(meta["sha256"]) == {"pcae.safetensors", "arrays.npz", "skill.yaml"}


def _bad_arrays(skill_arrays):
    k = skill_arrays["pomrp_hmm_means"].shape[0]
    nan_cov = skill_arrays["pomrp_hmm_covars"].copy()
    nan_cov[0, 0, 0] = np.nan
    rows = skill_arrays["pomrp_hmm_transmat"].copy()
    rows[0, 0] += 0.2
    return [
        ({"pomrp_hmm_covars": nan_cov}, r"pomrp_hmm_covars: contains NaN"),
        ({"pomrp_hmm_terminal_states": np.array([k + 3])},
         rf"pomrp_hmm_terminal_states: \[{k + 3}\], expected distinct states in \[0, {k}\)"),
        ({"pomrp_hmm_transmat": rows}, r"pomrp_hmm_transmat: row 0 sums to 1\.2"),
        ({"initial_index": np.array(5)}, r"initial_index: 5, expected an integer in \[0, 2\)"),
        ({"sigma0": np.zeros((10, 6, 6))}, r"sigma0: shape \(10, 6, 6\), expected \(10, 7, 7\)"),
        ({"sigma0": -np.broadcast_to(np.eye(7), (10, 7, 7)).copy()}, r"sigma0: a covariance is not positive definite"),
        ({"pomrp_values": np.array([1.0])}, r"pomrp_values: expected \d+ finite state values"),
        ({"pomrp_hmm_startprob": None}, r"missing array\(s\) \['pomrp_hmm_startprob'\]"),
    ]


def test_skill_load_rejects_bad_arrays(saved_skill, tmp_path):
    cases = _bad_arrays(load_npz(saved_skill / "arrays.npz"))
    for i, (changes, message) in enumerate(cases):
        directory = _copy(saved_skill, tmp_path / str(i))
        _rewrite_arrays(directory, **changes)
        with pytest.raises(ValueError, match=message) as err:
            Skill.load(directory)
        assert str(directory / "arrays.npz") in str(err.value)


def test_skill_load_rejects_config_that_disagrees_with_arrays(saved_skill, tmp_path):
    for i, (old, new, message) in enumerate([
            ("n_basis: 10", "n_basis: 12",
             r"dmp0_weights: shape \(10, 7\) disagrees with skill\.yaml \(dmp\.n_basis = 12"),
            ("skill: open", "skill: close", r"skill\.json: field 'skill' is 'open' but skill\.yaml says 'close'"),
            ("margin: 10.0", "margin: 3.0", r"pomrp\.off_model: skill\.yaml says .*margin=3\.0"),
            ("n_components: 8", "n_components: 6", r"pca_components: shape \(8, 128\) disagrees with skill\.yaml")]):
        directory = _copy(saved_skill, tmp_path / str(i))
        text = (directory / "skill.yaml").read_text()
        assert old in text
        (directory / "skill.yaml").write_text(text.replace(old, new, 1))
        _reseal(directory, "skill.yaml")
        with pytest.raises(ValueError, match=message):
            Skill.load(directory)


def test_skill_load_checksums_every_file(saved_skill, tmp_path):
    for name in ("arrays.npz", "skill.yaml", "pcae.safetensors"):
        directory = _copy(saved_skill, tmp_path / name)
        with open(directory / name, "ab") as f:
            f.write(b"\n")
        with pytest.raises(ValueError, match=rf"{name}: contents differ from the checksum in skill\.json"):
            Skill.load(directory)
        (directory / name).unlink()
        with pytest.raises(FileNotFoundError, match=rf"{name}: missing; the skill folder is incomplete"):
            Skill.load(directory)
    with pytest.raises(FileNotFoundError, match="no such skill folder"):
        Skill.load(tmp_path / "nowhere")
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="not a folder"):
        Skill.load(tmp_path / "file")


def test_version_1_skill_still_loads(saved_skill, tmp_path):
    """A skill saved before schema 2: pcae_sha256 only, no off-model range, no amplitude field."""
    directory = _copy(saved_skill, tmp_path)
    meta = json.loads((directory / "skill.json").read_text())
    for key in ("sha256", "skill"):
        meta.pop(key)
    meta["schema_version"] = 1
    meta["pomrp"].pop("off_model")
    _rewrite_arrays_plain = load_npz(directory / "arrays.npz")
    _rewrite_arrays_plain.pop("pomrp_frame_loglik_range")
    _rewrite_arrays_plain.pop("pomrp_data_covar")
    _rewrite_arrays_plain.pop("pomrp_references")
    atomic_save_npz(directory / "arrays.npz", _rewrite_arrays_plain)
    import yaml
    config = yaml.safe_load((directory / "skill.yaml").read_text())
    del config["dmp"]["scale_by_amplitude"], config["pomrp"]["off_model"]  # fields added with schema 2
    del config["cloud_frame"]                                                 # added with schema 3
    (directory / "skill.yaml").write_text(yaml.safe_dump(config))
    (directory / "skill.json").write_text(json.dumps(meta))
    skill = Skill.load(directory)
    assert skill.config.dmp.scale_by_amplitude  # the thesis form every version-1 skill was fitted with
    assert skill.config.cloud_frame == "world"  # and world-frame clouds
    assert not skill.pomrp.off_model_config.enabled and not skill.config.pomrp.off_model.enabled
    assert np.isfinite(skill.dense_return(skill.pomrp.goal_model.sample(20, 0)[0]))


def test_version_3_skill_holds_the_fingers_closed(saved_skill, tmp_path):
    """A skill saved before schema 4 has no gripper_opening: it was executed with closed fingers."""
    assert Skill.load(saved_skill).gripper_opening == pytest.approx(0.08)
    directory = _copy(saved_skill, tmp_path)
    arrays = load_npz(directory / "arrays.npz")
    arrays.pop("gripper_opening")
    atomic_save_npz(directory / "arrays.npz", arrays)
    meta = json.loads((directory / "skill.json").read_text())
    meta["schema_version"] = 3
    meta["sha256"]["arrays.npz"] = file_sha256(directory / "arrays.npz")
    (directory / "skill.json").write_text(json.dumps(meta))
    assert Skill.load(directory).gripper_opening == 0.0


@pytest.mark.parametrize("value", [0.5, -0.01, np.nan])
def test_out_of_range_gripper_opening_is_refused(saved_skill, tmp_path, value):
    directory = _copy(saved_skill, tmp_path)
    _rewrite_arrays(directory, gripper_opening=np.array(value))
    with pytest.raises(ValueError, match=r"gripper_opening: .* expected a finger opening in \[0, 0.08\] m"):
        Skill.load(directory)


def test_version_2_skill_encodes_world_frame_clouds(saved_skill, tmp_path):
    """A skill saved before schema 3 has no cloud_frame: its goal data came from world-frame clouds."""
    import yaml

    directory = _copy(saved_skill, tmp_path)
    meta = json.loads((directory / "skill.json").read_text())
    config = yaml.safe_load((directory / "skill.yaml").read_text())
    del config["cloud_frame"]
    (directory / "skill.yaml").write_text(yaml.safe_dump(config))
    meta["schema_version"] = 2
    meta["sha256"]["skill.yaml"] = file_sha256(directory / "skill.yaml")
    (directory / "skill.json").write_text(json.dumps(meta))
    skill = Skill.load(directory)
    assert skill.config.cloud_frame == "world"
    assert Skill.load(saved_skill).config.cloud_frame == "object"
    points = np.random.default_rng(0).uniform(0.3, 0.6, (3, 2048, 3))
    skill.goal_data(points)                           # world frame: no pose needed
    with pytest.raises(ValueError, match="pass X_WO"):
        Skill.load(saved_skill).goal_data(points)


def test_gripper_opening_is_the_demonstrations_median():
    from types import SimpleNamespace

    from drake_skill.fitted_skill import gripper_opening

    demos = [SimpleNamespace(gripper_100hz=np.r_[0.0, np.full(9, w)]) for w in (0.08, 0.07, 0.078)]
    assert gripper_opening(demos) == pytest.approx(0.078)
    assert gripper_opening([SimpleNamespace(), SimpleNamespace()]) == 0.0      # no gripper record: closed
    with pytest.raises(ValueError, match=r"demos\[1\].gripper_100hz: empty or not finite"):
        gripper_opening([demos[0], SimpleNamespace(gripper_100hz=np.array([0.0, np.nan]))])
