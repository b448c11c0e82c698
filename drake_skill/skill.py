"""A learned skill: action model + goal model, fitted from 2-3 demonstrations.

``fit_skill(demos, config)`` (docs/method.md sections 2-4, thesis chapters 4-6):

1. action model: one DMP per demonstration fitted to the 10 Hz hand poses in
   the object frame; the initial policy weights are one of them (drawn by
   seed) and the per-basis exploration covariances Sigma_b^0 their sample
   covariance plus a ridge (``drake_skill.action.dmp.fit_demonstrations``);
2. perception: every demonstration frame's segmented object cloud (2048
   points) is encoded by the PCAE into a 128-D code (frames where the object
   was not seen hold the last seen code, as ``PcaeFeaturizer`` does online);
   a PCA fitted on all demonstration codes maps them to 8-D goal data;
3. goal model: a Gaussian HMM over the goal data (states chosen by AIC),
   terminal states, MRP state values, and the POMRP reward / verdict
   (``drake_skill.reward.pomrp.fit_pomrp``).

A :class:`Skill` saves to a directory and loads back identical, without
pickle::

    skill.yaml          SkillConfig (yaml_load_typed) + summary
    skill.json          metadata: schema version, goal-model metadata, info
    arrays.npz          DMPs, Sigma_0, PCA, HMM arrays, state values
    pcae.safetensors    the encoder weights the goal data were made with
"""

import dataclasses as dc
import hashlib
import json
import shutil
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

from drake_skill.action.dmp import Dmp, DmpConfig, fit_demonstrations
from drake_skill.fileio import atomic_save_npz, atomic_write_json, atomic_write_text, load_npz
from drake_skill.perception.features import GoalFeatures, GoalFeaturesConfig
from drake_skill.reward.pomrp import Pomrp, PomrpConfig, fit_pomrp
from drake_skill.station.config import SKILLS

SCHEMA_VERSION = 1

# Thesis Table 6.1 (simulation: Open 20, Close 10; real robot: Draw 9).
DEFAULT_BASES = {"open": 20, "close": 10, "draw": 9}


@dc.dataclass
class SkillConfig:
    """Everything ``fit_skill`` needs (loadable with ``yaml_load_typed``).

    skill: "open", "close" or "draw".
    dmp: DMP hyper-parameters (n_basis defaults per skill, thesis Table 6.1).
    dmp_ridge: relative ridge of Sigma_b^0 (``drake_skill.action.dmp.exploration_covariance``).
    seed: picks the demonstration whose DMP starts policy search.
    goal_features: PCA size (8).
    pomrp: goal HMM, MRP and verdict settings.
    pcae_weights: the PCAE safetensors file ("" = the shipped models/pcae.safetensors).
    """

    skill: str = "open"
    dmp: DmpConfig = dc.field(default_factory=DmpConfig)
    dmp_ridge: float = 0.1
    seed: int = 0
    goal_features: GoalFeaturesConfig = dc.field(default_factory=GoalFeaturesConfig)
    pomrp: PomrpConfig = dc.field(default_factory=PomrpConfig)
    pcae_weights: str = ""


def default_skill_config(skill: str) -> SkillConfig:
    """SkillConfig with the thesis' number of DMP bases for ``skill``."""
    if skill not in SKILLS:
        raise ValueError(f"skill {skill!r}: expected one of {', '.join(SKILLS)}")
    return SkillConfig(skill=skill, dmp=DmpConfig(n_basis=DEFAULT_BASES[skill]))


def _pcae_path(config: SkillConfig) -> Path:
    from drake_skill.perception.pcae import DEFAULT_WEIGHTS
    return Path(config.pcae_weights) if config.pcae_weights else Path(DEFAULT_WEIGHTS)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def hold_invalid(codes: np.ndarray, valid: np.ndarray, name: str = "frames") -> np.ndarray:
    """Replaces codes of frames where the object was not seen by the last seen code.

    Frames before the first seen one take the first seen code. Raises
    ValueError if no frame saw the object.
    """
    valid = np.asarray(valid, dtype=bool)
    if not valid.any():
        raise ValueError(f"{name}: the object was never segmented (all {valid.size} frames invalid)")
    out = codes.copy()
    last = codes[np.argmax(valid)]
    for t in range(len(out)):
        if valid[t]:
            last = codes[t]
        else:
            out[t] = last
    return out


def encode_sequence(encoder, object_points, valid=None, name: str = "object_points") -> np.ndarray:
    """PCAE codes (T, 128) of (T, N, 3) clouds; frames not valid hold the last valid code."""
    points = np.asarray(object_points, dtype=np.float32)
    if points.ndim != 3 or points.shape[2] != 3:
        raise ValueError(f"{name}: expected shape (T, N, 3), got {points.shape}")
    valid = np.ones(len(points), bool) if valid is None else np.asarray(valid, bool)
    if valid.shape != (len(points),):
        raise ValueError(f"{name}: validity flags of shape {valid.shape} do not match {len(points)} frames")
    codes = np.zeros((len(points), encoder.code_size), np.float32)
    if valid.any():
        codes[valid] = encoder.encode_points(points[valid])
    return hold_invalid(codes, valid, name)


@dc.dataclass
class Skill:
    """A fitted skill (see the module docstring).

    dmps: one per demonstration; initial_index: the DMP policy search starts
    from; sigma0: (B, 7, 7) Sigma_b^0; goal_features: fitted PCA; pomrp: goal
    HMM + state values; pcae_weights: path of the encoder weights;
    info: JSON-able summary (explained variance, demonstration names, ...).
    """

    config: SkillConfig
    dmps: list
    initial_index: int
    sigma0: np.ndarray
    goal_features: GoalFeatures
    pomrp: Pomrp
    pcae_weights: Path
    info: dict

    @property
    def name(self) -> str:
        return self.config.skill

    @property
    def initial_dmp(self) -> Dmp:
        return self.dmps[self.initial_index]

    @property
    def initial_weights(self) -> np.ndarray:
        """W0 (B, 7): the weights policy search starts from."""
        return self.initial_dmp.weights.copy()

    # ------------------------------------------------------------ perception
    def encoder(self):
        from drake_skill.perception.pcae import load_pcae
        if getattr(self, "_encoder", None) is None:
            self._encoder = load_pcae(self.pcae_weights)
        return self._encoder

    def codes(self, object_points, valid=None, name: str = "object_points") -> np.ndarray:
        """PCAE codes (T, 128) of (T, 2048, 3) clouds; invalid frames hold the last valid code."""
        return encode_sequence(self.encoder(), object_points, valid, name)

    def goal_data(self, object_points, valid=None) -> np.ndarray:
        """Goal data G (T, 8) of an execution's object clouds (T, 2048, 3)."""
        return self.goal_features.transform(self.codes(object_points, valid))

    # ------------------------------------------------------------ rewards
    def dense_return(self, G) -> float:
        """R(G), thesis Eq. 4.5."""
        return self.pomrp.episode_return(G)

    def verdict(self, G) -> bool:
        """The goal model's success verdict (sparse reward)."""
        return self.pomrp.verdict(G)

    def summary(self) -> str:
        hmm = self.pomrp.goal_model
        lines = [
            f"skill '{self.name}': {len(self.dmps)} demonstrations, DMP B = {self.config.dmp.n_basis}, "
            f"initial weights from demonstration {self.initial_index}",
            f"PCA 128 -> {self.goal_features.n_components}: explained variance "
            f"{100 * self.info['pca_explained_variance']:.1f} %",
            f"goal HMM: {hmm.n_states_} states ({hmm.covariance_type_} covariance, "
            f"{self.config.pomrp.goal_model.criterion.upper()}), terminal states "
            f"{list(map(int, self.pomrp.terminal_states))}",
            "state values: " + ", ".join(f"{i}: {v:.2f}" for i, v in enumerate(self.pomrp.values)),
            "demonstrations: " + ", ".join(
                f"R = {r:.1f} ({'success' if ok else 'failure'})"
                for r, ok in zip(self.info["demo_returns"], self.info["demo_verdicts"])),
        ]
        return "\n".join(lines)

    # ------------------------------------------------------------ save/load
    def save(self, directory, overwrite: bool = False) -> Path:
        """Writes the skill to ``directory`` (refuses to overwrite unless asked)."""
        directory = Path(directory)
        if (directory / "skill.json").exists() and not overwrite:
            raise FileExistsError(f"{directory} already holds a skill; pass overwrite=True to replace it")
        directory.mkdir(parents=True, exist_ok=True)
        arrays = {"sigma0": self.sigma0, "initial_index": np.array(self.initial_index)}
        for i, dmp in enumerate(self.dmps):
            arrays.update(dmp.to_arrays(prefix=f"dmp{i}_"))
        arrays.update({f"pca_{k}": v for k, v in self.goal_features.to_arrays().items()})
        pomrp_arrays, pomrp_meta = self.pomrp.to_arrays()
        arrays.update({f"pomrp_{k}": v for k, v in pomrp_arrays.items()})
        weights = directory / "pcae.safetensors"
        if self.pcae_weights.resolve() != weights.resolve():
            shutil.copyfile(self.pcae_weights, weights.with_suffix(".tmp"))
            weights.with_suffix(".tmp").replace(weights)
        atomic_save_npz(directory / "arrays.npz", arrays)
        atomic_write_text(directory / "skill.yaml", yaml_dump_typed(self.config))
        atomic_write_json(directory / "skill.json", {
            "schema": "drake_skill.skill", "schema_version": SCHEMA_VERSION,
            "n_demonstrations": len(self.dmps), "pomrp": pomrp_meta, "info": self.info,
            "pcae_sha256": _sha256(weights)})
        return directory

    @classmethod
    def load(cls, directory) -> "Skill":
        """Reads a skill written by :meth:`save`; errors name the file and what is wrong."""
        directory = Path(directory)
        meta_path = directory / "skill.json"
        if not meta_path.is_file():
            raise FileNotFoundError(f"{directory}: no skill.json (not a skill directory)")
        try:
            meta = json.loads(meta_path.read_text())
        except json.JSONDecodeError as e:
            raise ValueError(f"{meta_path}: not valid JSON ({e})") from e
        if meta.get("schema") != "drake_skill.skill" or meta.get("schema_version") != SCHEMA_VERSION:
            raise ValueError(f"{meta_path}: schema {meta.get('schema')!r} version "
                             f"{meta.get('schema_version')!r}, expected drake_skill.skill {SCHEMA_VERSION}")
        try:
            config = yaml_load_typed(schema=SkillConfig, filename=str(directory / "skill.yaml"),
                                     defaults=SkillConfig())
        except RuntimeError as e:
            raise ValueError(f"{directory / 'skill.yaml'}: {e}") from e
        arrays = load_npz(directory / "arrays.npz")
        weights = directory / "pcae.safetensors"
        if not weights.is_file():
            raise FileNotFoundError(f"{weights}: the skill's PCAE weights are missing")
        if _sha256(weights) != meta.get("pcae_sha256"):
            raise ValueError(f"{weights}: contents differ from the weights the skill was fitted with")
        try:
            n = int(meta["n_demonstrations"])
            dmps = [Dmp.from_arrays(arrays, prefix=f"dmp{i}_") for i in range(n)]
            pca = GoalFeatures.from_arrays({k[4:]: v for k, v in arrays.items() if k.startswith("pca_")})
            pomrp = Pomrp.from_arrays({k[6:]: v for k, v in arrays.items() if k.startswith("pomrp_")},
                                      meta["pomrp"])
            return cls(config, dmps, int(arrays["initial_index"]), arrays["sigma0"], pca, pomrp,
                       weights, meta["info"])
        except (KeyError, ValueError) as e:
            raise ValueError(f"{directory / 'arrays.npz'}: {e}") from e


def fit_skill(demos: Sequence, config: SkillConfig | None = None) -> Skill:
    """Fits a skill from demonstrations (objects with ``times``, ``X_OE``,
    ``object_points``, ``perception_valid``, e.g. ``drake_skill.demos.format.Demonstration``).
    """
    config = config if config is not None else default_skill_config("open")
    if len(demos) < 2:
        raise ValueError(f"demos: need at least 2 demonstrations of '{config.skill}', got {len(demos)}")
    for i, demo in enumerate(demos):
        if getattr(demo, "object_points", None) is None:
            raise ValueError(f"demos[{i}]: recorded without perception (no object_points); "
                             "record demonstrations with the camera on")
        skill = getattr(demo, "skill", config.skill)
        if skill != config.skill:
            raise ValueError(f"demos[{i}]: a '{skill}' demonstration given to fit '{config.skill}'")

    fit = fit_demonstrations([(d.times, d.X_OE) for d in demos], config.dmp,
                             seed=config.seed, ridge=config.dmp_ridge)

    from drake_skill.perception.pcae import load_pcae
    weights = _pcae_path(config)
    encoder = load_pcae(weights)
    pca = GoalFeatures.from_config(config.goal_features)
    codes = [encode_sequence(encoder, d.object_points, d.perception_valid, f"demos[{i}].perception_valid")
             for i, d in enumerate(demos)]
    lengths = np.array([len(c) for c in codes])
    pca.fit(np.concatenate(codes), lengths)
    goal = [pca.transform(c) for c in codes]
    pomrp = fit_pomrp(np.concatenate(goal), lengths, config.pomrp)
    info: dict[str, Any] = {
        "pca_explained_variance": float(pca.total_explained_variance_ratio),
        "pca_explained_variance_ratio": [float(v) for v in pca.explained_variance_ratio_],
        "demo_lengths": [int(n) for n in lengths],
        "demo_returns": [float(pomrp.episode_return(G)) for G in goal],
        "demo_verdicts": [bool(pomrp.verdict(G)) for G in goal],
        "demo_names": [str(getattr(d, "metadata", {}).get("file", f"demo {i}"))
                       if isinstance(getattr(d, "metadata", None), dict) else f"demo {i}"
                       for i, d in enumerate(demos)],
    }
    skill = Skill(config, fit.dmps, fit.initial_index, fit.sigma0, pca, pomrp, weights, info)
    skill._encoder = encoder
    return skill
