"""A learned skill: action model + goal model, fitted from 2-3 demonstrations.

``fit_skill(demos, config)`` (docs/method.md sections 2-4, thesis chapters 4-6):

1. action model: one DMP per demonstration fitted to the 10 Hz hand poses in
   the object frame; the initial policy weights are one of them (drawn by
   seed) and the per-basis exploration covariances Sigma_b^0 their sample
   covariance plus a ridge (``drake_skill.action.dmp.fit_demonstrations``);
   the gripper is not part of the DMP: the skill holds the demonstrations'
   finger opening (``gripper_opening``, the median of their commanded
   openings) for the whole execution (docs/method.md section 2);
2. perception: every demonstration frame's segmented object cloud (2048
   points), expressed in the demonstration's perceived object frame
   (``SkillConfig.cloud_frame``), is encoded by the PCAE into a 128-D code (frames where the object
   was not seen hold the last seen code, as ``PcaeFeaturizer`` does online);
   a PCA fitted on all demonstration codes maps them to 8-D goal data;
3. goal model: a Gaussian HMM over the goal data (states chosen by AIC),
   terminal states, MRP state values, and the POMRP reward / verdict
   (``drake_skill.reward.pomrp.fit_pomrp``).

A :class:`Skill` saves to a directory and loads back identical, without
pickle::

    skill.yaml          SkillConfig (yaml_load_typed)
    skill.json          metadata: schema version, skill name, SHA-256 of the
                        three other files, goal-model metadata, info
    arrays.npz          DMPs, Sigma_0, PCA, HMM arrays, state values
    pcae.safetensors    the encoder weights the goal data were made with

The directory is written as one unit (a new directory swapped in), and
:meth:`Skill.load` validates it as strictly as a fit.
"""

import dataclasses as dc
import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from pydrake.common.yaml import yaml_dump_typed

from drake_skill.action.dmp import Dmp, DmpConfig, fit_demonstrations
from drake_skill.action.fitting import FitTolerance, choose_n_basis, contact_mask, fit_errors
from drake_skill import fileio
from drake_skill.typed_yaml import load_typed
from drake_skill.perception.features import GoalFeatures, GoalFeaturesConfig
from drake_skill.reward.pomrp import Pomrp, PomrpConfig, fit_pomrp
from drake_skill.skills import SkillSpec, load_skill
from drake_skill.station.limits import FINGER_MAX

#: skill.json's format name: the module's name when the format was made (drake_skill/skill.py, renamed
#: fitted_skill.py), kept so that every saved skill still loads.
SCHEMA = "drake_skill.skill"
SCHEMA_VERSION = 5

@dc.dataclass
class SkillConfig:
    """Everything ``fit_skill`` needs (loadable with ``yaml_load_typed``).

    skill: the skill's name (``spec.name``).
    spec: the skill file it was fitted for (docs/skills.md): its scenario,
      success rule, exploration scale and gripper opening travel with it.
    dmp: DMP hyper-parameters (n_basis: the skill file's ``dmp_bases``, or
      chosen from ``dmp_tolerance`` when the skill file leaves it out).
    dmp_data: which action data the DMPs fit (docs/method.md section 2.2):
      "100hz" (default), the measured hand pose at the recording rate, whose
      first samples read the start at rest; "10hz", the 10 Hz samples of
      thesis 6.3, whose numerical derivative reads a spurious start velocity
      (skills fitted before 2026-12-06 and the chapter-7 grid).
    dmp_tolerance: how closely each integrated DMP must follow its
      demonstration when the skill file leaves ``dmp_bases`` out
      (``drake_skill.action.fitting.FitTolerance``).
    dmp_refine: refinement steps on the simulated station after the fit
      (``drake_skill.learning.refine``, docs/method.md section 2.3); 0: off.
      ``fit_skill`` itself never simulates; ``drake-skill fit`` and ``learn``
      apply it.
    dmp_ridge: relative ridge of Sigma_b^0 (``drake_skill.action.dmp.exploration_covariance``).
    exploration_bases: Sigma_b^0 is estimated from fits with this many bases
      when the fit chose more (docs/method.md section 2.2); 0: from the
      fits themselves, as the thesis does.
    seed: picks the demonstration whose DMP starts policy search.
    goal_features: PCA size (8).
    pomrp: goal HMM, MRP and verdict settings.
    pcae_weights: the PCAE safetensors file ("" = the shipped models/pcae.safetensors).
    cloud_frame: the frame the object clouds are encoded in: "object" (default,
      docs/method.md section 3: the perceived object frame X_WO of the
      execution's first valid camera frame, which removes the object's yaw
      and position on the table) or "world" (the thesis's; skills saved
      before schema version 3).
    """

    skill: str = ""
    spec: SkillSpec = dc.field(default_factory=SkillSpec)
    dmp: DmpConfig = dc.field(default_factory=DmpConfig)
    dmp_data: str = "100hz"
    dmp_tolerance: FitTolerance = dc.field(default_factory=FitTolerance)
    dmp_refine: int = 1
    exploration_bases: int = 20
    dmp_ridge: float = 0.1
    seed: int = 0
    goal_features: GoalFeaturesConfig = dc.field(default_factory=GoalFeaturesConfig)
    pomrp: PomrpConfig = dc.field(default_factory=PomrpConfig)
    pcae_weights: str = ""
    cloud_frame: str = "object"


CLOUD_FRAMES = ("object", "world")
DMP_DATA = ("100hz", "10hz")
#: The names of the vector DMP's weight columns (docs/method.md section 2).
DMP_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")


#: How a skill's DMPs are fitted (docs/method.md section 2.2): "tolerance" (the
#: default) or "thesis", the fit of the chapter-7 grid (thesis 6.3 and Table 6.1).
FITS = ("tolerance", "thesis")
#: Thesis Table 6.1's bases (Draw: its real-robot value); a skill the thesis
#: does not have keeps its skill file's ``dmp_bases``, else THESIS_DMP_BASES_OTHER.
THESIS_DMP_BASES = {"open": 20, "close": 10, "draw": 9}
THESIS_DMP_BASES_OTHER = 10


def default_skill_config(skill, fit: str = "tolerance") -> SkillConfig:
    """SkillConfig of a skill (a shipped skill's name, a skill file or a SkillSpec),
    with the skill file's number of DMP bases (if it fixes one) and unscaled DMP columns.

    The learned reward is the skill file's ``reward`` (docs/method.md section 4.4).
    ``fit = "thesis"``: the fit of the committed chapter-7 grid instead: the
    10 Hz action data, Table 6.1's bases, the amplitude rule for scaled
    columns (docs/method.md section 2.2) and the thesis's state reward.
    """
    if fit not in FITS:
        raise ValueError(f"fit: {fit!r}; expected one of {', '.join(FITS)}")
    spec = load_skill(skill)
    dmp = DmpConfig(unscaled_dims=[int(i) for i in spec.dmp_unscaled_dims])
    if fit == "thesis":
        bases = THESIS_DMP_BASES.get(spec.name, spec.dmp_bases or THESIS_DMP_BASES_OTHER)
        spec = dc.replace(spec, dmp_bases=int(bases))
        dmp = dc.replace(dmp, scale_rule="amplitude")
        return SkillConfig(skill=spec.name, spec=spec, dmp=dc.replace(dmp, n_basis=int(bases)), dmp_data="10hz",
                           dmp_refine=0)
    if spec.dmp_bases is not None:
        dmp.n_basis = int(spec.dmp_bases)
    return SkillConfig(skill=spec.name, spec=spec, dmp=dmp, pomrp=PomrpConfig(reward=spec.reward))


def _pcae_path(config: SkillConfig) -> Path:
    from drake_skill.perception.pcae import default_weights
    return Path(config.pcae_weights) if config.pcae_weights else default_weights()


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


def encode_sequence(encoder, object_points, valid=None, name: str = "object_points", X_WO=None) -> np.ndarray:
    """PCAE codes (T, 128) of (T, N, 3) world-frame clouds; frames not valid hold the last valid code.

    With ``X_WO`` ((7,) xyz + wxyz or (4, 4)) the clouds are expressed in that
    frame first (``drake_skill.perception.pcae.cloud_in_object_frame``).
    """
    points = np.asarray(object_points, dtype=np.float32)
    if points.ndim != 3 or points.shape[2] != 3:
        raise ValueError(f"{name}: expected shape (T, N, 3), got {points.shape}")
    if X_WO is not None:
        from drake_skill.perception.pcae import cloud_in_object_frame
        points = cloud_in_object_frame(points, X_WO)
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
    info: JSON-able summary (explained variance, demonstration names, ...);
    gripper_opening: the finger opening [m] commanded throughout an
    execution (:func:`gripper_opening`).
    """

    config: SkillConfig
    dmps: list
    initial_index: int
    sigma0: np.ndarray
    goal_features: GoalFeatures
    pomrp: Pomrp
    pcae_weights: Path
    info: dict
    gripper_opening: float = 0.0

    @property
    def name(self) -> str:
        return self.config.skill

    @property
    def spec(self) -> SkillSpec:
        """The skill file the skill was fitted for."""
        return self.config.spec

    def station_config(self):
        """The skill's scenario with its success rule (a fresh Scenario)."""
        return self.config.spec.station_config()

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

    def codes(self, object_points, valid=None, name: str = "object_points", X_WO=None) -> np.ndarray:
        """PCAE codes (T, 128) of (T, 2048, 3) world-frame clouds; invalid frames hold the last valid code.

        X_WO: the execution's perceived object pose ((7,) xyz + wxyz, e.g.
        ``Demonstration.X_WO_start`` or ``RolloutResult.object_pose``, or a
        RigidTransform); required when ``config.cloud_frame`` is "object".
        """
        if self.config.cloud_frame == "object":
            if X_WO is None:
                raise ValueError(f"skill '{self.name}' encodes clouds in the object frame: pass X_WO, the "
                                 "execution's perceived object pose (Demonstration.X_WO_start, "
                                 "RolloutResult.object_pose)")
            if hasattr(X_WO, "GetAsMatrix4"):
                X_WO = X_WO.GetAsMatrix4()
        else:
            X_WO = None
        return encode_sequence(self.encoder(), object_points, valid, name, X_WO=X_WO)

    def goal_data(self, object_points, valid=None, X_WO=None) -> np.ndarray:
        """Goal data G (T, 8) of an execution's object clouds (T, 2048, 3) (X_WO: see :meth:`codes`)."""
        return self.goal_features.transform(self.codes(object_points, valid, X_WO=X_WO))

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
            f"initial weights from demonstration {self.initial_index}"
            f"{' (best learned return)' if 'initial_choice' in self.info else ''}, "
            f"finger opening {1000 * self.gripper_opening:.0f} mm",
            f"PCA 128 -> {self.goal_features.n_components}: explained variance "
            f"{100 * self.info['pca_explained_variance']:.1f} %",
            f"goal HMM: {hmm.n_states_} states ({hmm.covariance_type_} covariance, "
            f"{self.config.pomrp.goal_model.criterion.upper()}), terminal states "
            f"{list(map(int, self.pomrp.terminal_states))}",
            "state values: " + ", ".join(f"{i}: {v:.2f}" for i, v in enumerate(self.pomrp.values)),
            self._reward_line(),
            (f"off-model guard: frames below {self.pomrp.explained_floor:.1f} nats (demonstrations' lowest "
             f"{self.pomrp.frame_loglik_range[0]:.1f} - {self.pomrp.off_model_config.margin:g}) earn less reward "
             "and fail the verdict" if self.pomrp.off_model_config.enabled
             else "off-model guard: off (the thesis's plain reward and verdict)"),
            "demonstrations: " + ", ".join(
                f"R = {r:.1f} ({'success' if ok else 'failure'})"
                for r, ok in zip(self.info["demo_returns"], self.info["demo_verdicts"])),
        ]
        return "\n".join(lines)

    def _reward_line(self) -> str:
        p = self.pomrp
        if p.reward_kind == "states":
            return "reward: the goal HMM's state values (thesis Eq. 4.4-4.5), verdict: final Viterbi state terminal"
        return (f"reward: progress along the demonstrated change x {p.progress_config.scale:g} (docs/method.md "
                f"4.4), verdict: progress >= {(1 - p.progress_config.tolerance) * p.progress_least:.2f} "
                f"({1 - p.progress_config.tolerance:g} x the least demonstration's {p.progress_least:.2f})")

    def fit_report(self) -> tuple[list[str], list[str]]:
        """``(lines, warnings)`` on the DMP fit (docs/method.md section 2.2): B and how it was
        chosen, each demonstration's fit error, the scaled columns; a warning for a
        demonstration that misses the tolerance or never moves the object. Empty for
        skills fitted before the report existed."""
        report = self.info.get("dmp_fit")
        if not report:
            return [], []
        tol = report["tolerance"]
        lines = [f"DMP: B = {report['n_basis']} bases ({report['how']}; tolerance {tol['contact_max_mm']:g} mm "
                 f"near contact, {tol['rms_mm']:g} mm RMS), fitted to the {report['data']} action data"]
        warnings = []
        for e in report["errors"]:
            lines.append(f"  {e['demo']}: fit error max {e['fit_max_mm']:.1f} mm, RMS {e['fit_rms_mm']:.1f} mm, "
                         f"near contact {e['fit_contact_max_mm']:.1f} mm ({e['contact_samples']} samples)")
            if e["fit_rms_mm"] > tol["rms_mm"] or e["fit_contact_max_mm"] > tol["contact_max_mm"]:
                warnings.append(f"{e['demo']}: the DMP misses it by {e['fit_contact_max_mm']:.1f} mm near contact "
                                f"and {e['fit_rms_mm']:.1f} mm RMS, more than the tolerance; remove dmp_bases "
                                "from the skill file to choose B from the tolerance")
            if e["contact_samples"] == 0 and report.get("object_state_known", True):
                warnings.append(f"{e['demo']}: the object's joint never moves in it (no contact); check that "
                                "the demonstration touches the object, or record it again")
        names = DMP_COLUMNS if self.config.dmp.quaternion == "vector" else ("x", "y", "z", "rx", "ry", "rz")
        by_reason: dict[str, list] = {}
        for k, why in report["scaled"].items():
            by_reason.setdefault(why, []).append(names[int(k)])
        if report.get("start_join"):
            lines.append(f"a start away from the demonstrated one joins the demonstrated path within "
                         f"{100 * report['start_join']:.0f} % of the duration, before the first contact")
        lines.append("columns scaled by g - y0: " + (", ".join(by_reason.pop("scaled", [])) or "none") + "; not: "
                     + "; ".join(f"{', '.join(cols)} ({why})" for why, cols in by_reason.items()))
        return lines, warnings

    # ------------------------------------------------------------ save/load
    def save(self, directory, overwrite: bool = False) -> Path:
        """Writes the skill to ``directory`` as one unit (refuses to overwrite unless asked).

        The files are written into a new sibling directory which then
        replaces ``directory`` in one swap (:class:`drake_skill.fileio.staged_directory`),
        so an interruption leaves the whole old skill or the whole new one.
        ``skill.json`` records the SHA-256 of every other file; :meth:`load`
        checks them. Other files in an existing skill ``directory`` (the fit
        command's pictures, a user's notes) are carried over; a non-empty
        ``directory`` that holds no skill is refused.
        """
        directory = Path(directory)
        if directory.exists() and not directory.is_dir():
            raise NotADirectoryError(f"{directory}: exists and is not a directory; choose a folder for the skill")
        if (directory / "skill.json").exists() and not overwrite:
            raise FileExistsError(f"{directory} already holds a skill; pass overwrite=True (--force) to replace it")
        if directory.is_dir() and any(directory.iterdir()) and not (directory / "skill.json").exists():
            raise FileExistsError(f"{directory}: exists, is not empty and holds no skill; choose an empty "
                                  "or new folder for the skill")
        arrays = {"sigma0": self.sigma0, "initial_index": np.array(self.initial_index),
                  "gripper_opening": np.array(float(self.gripper_opening))}
        for i, dmp in enumerate(self.dmps):
            arrays.update(dmp.to_arrays(prefix=f"dmp{i}_"))
        arrays.update({f"pca_{k}": v for k, v in self.goal_features.to_arrays().items()})
        pomrp_arrays, pomrp_meta = self.pomrp.to_arrays()
        arrays.update({f"pomrp_{k}": v for k, v in pomrp_arrays.items()})
        weights_bytes = Path(self.pcae_weights).read_bytes()
        with fileio.staged_directory(directory, overwrite=True) as tmp:
            fileio.carry_over(directory, tmp, exclude={*_SKILL_FILES, "skill.json"})
            fileio.atomic_write_bytes(tmp / "pcae.safetensors", weights_bytes)
            fileio.atomic_save_npz(tmp / "arrays.npz", arrays)
            fileio.atomic_write_text(tmp / "skill.yaml", yaml_dump_typed(self.config))
            files = {name: fileio.file_sha256(tmp / name) for name in _SKILL_FILES}
            fileio.atomic_write_json(tmp / "skill.json", {
                "schema": SCHEMA, "schema_version": SCHEMA_VERSION, "skill": self.name,
                "n_demonstrations": len(self.dmps), "pomrp": pomrp_meta, "info": self.info,
                "sha256": files, "pcae_sha256": files["pcae.safetensors"]})
        return directory

    @classmethod
    def load(cls, directory) -> "Skill":
        """Reads a skill written by :meth:`save`, validated as strictly as a fitted one.

        Errors (FileNotFoundError, NotADirectoryError, ValueError) name the
        file and the field. Checked: every file's SHA-256 against
        ``skill.json`` (a partial or mixed set fails), ``skill.yaml`` against
        the arrays (skill name, ``n_basis``, quaternion mode, PCA size,
        reward settings), the DMPs, ``initial_index``, ``Sigma_0`` (shape,
        finite, symmetric positive definite), the PCA and the goal HMM
        (:meth:`drake_skill.reward.goal_model.GoalHMM.from_arrays`).

        Skills saved with schema version 1 (before the checksums of every
        file, the DMP amplitude default and the off-model guard) still load:
        only ``pcae.safetensors`` is checksummed, a DMP field absent from
        their ``skill.yaml`` takes the thesis form (``scale_by_amplitude:
        true``, what every version-1 skill was fitted with), and the
        off-model guard is off (the demonstrations' range was not recorded).
        """
        directory = Path(directory)
        if not directory.exists():
            aside = fileio.interrupted_swap(directory)
            hint = f"; an interrupted save left the previous skill in {aside[-1]}" if aside else ""
            raise FileNotFoundError(f"{directory}: no such skill folder (no skill.json){hint}")
        if not directory.is_dir():
            raise NotADirectoryError(f"{directory}: not a folder; expected a skill folder written by Skill.save")
        meta_path = directory / "skill.json"
        if not meta_path.is_file():
            raise FileNotFoundError(f"{directory}: no skill.json (not a skill directory)")
        try:
            meta = json.loads(meta_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise ValueError(f"{meta_path}: not valid JSON ({e})") from e
        if not isinstance(meta, dict):
            raise ValueError(f"{meta_path}: expected a JSON object")
        version = meta.get("schema_version")
        if meta.get("schema") != SCHEMA or version not in _READABLE_VERSIONS:
            raise ValueError(f"{meta_path}: schema {meta.get('schema')!r} version {version!r}, expected "
                             f"drake_skill.fitted_skill version {' or '.join(map(str, _READABLE_VERSIONS))}")
        _check_checksums(directory, meta, version)
        config = _load_config(directory / "skill.yaml", version)
        arrays = fileio.load_npz(directory / "arrays.npz")
        weights = directory / "pcae.safetensors"
        where = directory / "arrays.npz"
        try:
            skill = _skill_from_arrays(config, arrays, meta, weights, version)
        except KeyError as e:
            raise ValueError(f"{where}: missing entry {e}") from e
        except ValueError as e:
            if str(e).startswith(str(directory)):
                raise
            raise ValueError(f"{where}: {e}") from e
        return skill


_SKILL_FILES = ("pcae.safetensors", "arrays.npz", "skill.yaml")
_READABLE_VERSIONS = (1, 2, 3, 4, 5)


def _check_checksums(directory: Path, meta: dict, version: int) -> None:
    """Every file of the skill against the SHA-256 recorded in skill.json."""
    meta_path = directory / "skill.json"
    for name in _SKILL_FILES:
        if not (directory / name).is_file():
            raise FileNotFoundError(f"{directory / name}: missing; the skill folder is incomplete "
                                    "(copy the whole folder, or fit the skill again)")
    if version == 1:
        expected = {"pcae.safetensors": meta.get("pcae_sha256")}
    else:
        expected = meta.get("sha256")
        if not isinstance(expected, dict) or set(expected) != set(_SKILL_FILES):
            raise ValueError(f"{meta_path}: field 'sha256' must list {', '.join(_SKILL_FILES)}")
    for name, digest in expected.items():
        if fileio.file_sha256(directory / name) != digest:
            raise ValueError(f"{directory / name}: contents differ from the checksum in {meta_path.name} "
                             "(a partial copy, an edit, or files of two different skills); "
                             "restore the folder or fit the skill again")


def _load_config(path: Path, version: int) -> SkillConfig:
    defaults = SkillConfig()
    if version == 1:
        # Every version-1 skill was fitted with the thesis's amplitude scaling.
        defaults.dmp.scale_by_amplitude = True
    if version <= 2:
        # Skills before version 3 encoded world-frame clouds.
        defaults.cloud_frame = "world"
    config = load_typed(SkillConfig, what="skill config", path=path, defaults=defaults)
    if not config.spec.name:
        # Skills fitted before skill files (schema version 4) name a shipped skill.
        try:
            config.spec = load_skill(config.skill)
        except FileNotFoundError as e:
            raise ValueError(f"{path}: field 'skill' is {config.skill!r}, not a shipped skill, and the file "
                             "holds no 'spec'; fit the skill again from its skill file") from e
    if config.spec.name != config.skill:
        raise ValueError(f"{path}: field 'skill' is {config.skill!r} but 'spec.name' is {config.spec.name!r}; "
                         "the file was edited; fit the skill again")
    if config.cloud_frame not in CLOUD_FRAMES:
        raise ValueError(f"{path}: field 'cloud_frame' is {config.cloud_frame!r}; expected one of "
                         f"{', '.join(CLOUD_FRAMES)}")
    try:
        config.dmp.validate()
    except ValueError as e:
        raise ValueError(f"{path}: field 'dmp': {e}") from e
    return config


def _skill_from_arrays(config: SkillConfig, arrays: dict, meta: dict, weights: Path, version: int) -> "Skill":
    yaml_path = weights.with_name("skill.yaml")
    json_path = weights.with_name("skill.json")
    if version >= 2 and meta.get("skill") != config.skill:
        raise ValueError(f"{json_path}: field 'skill' is {meta.get('skill')!r} but {yaml_path.name} says "
                         f"{config.skill!r}; the files come from different skills")
    try:
        n = int(meta["n_demonstrations"])
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{json_path}: field 'n_demonstrations' missing or not an integer") from e
    if n < 1:
        raise ValueError(f"{json_path}: field 'n_demonstrations' is {n}; expected >= 1")
    dmps = []
    for i in range(n):
        try:
            dmp = Dmp.from_arrays(arrays, prefix=f"dmp{i}_")
        except ValueError as e:
            raise ValueError(f"dmp{i}: {e}") from e
        dmps.append(dmp)
    B, d = config.dmp.n_basis, config.dmp.weight_dim
    for i, dmp in enumerate(dmps):
        if dmp.weights.shape != (B, d):
            raise ValueError(f"dmp{i}_weights: shape {dmp.weights.shape} disagrees with {yaml_path.name} "
                             f"(dmp.n_basis = {B}, dmp.quaternion = {config.dmp.quaternion!r}: expected ({B}, {d}))")
    raw_index = np.asarray(arrays["initial_index"])
    if raw_index.shape != () or raw_index.dtype.kind not in "iu" or not 0 <= int(raw_index) < n:
        raise ValueError(f"initial_index: {raw_index.tolist()!r}, expected an integer in [0, {n}) "
                         f"(one of the {n} demonstrations)")
    sigma0 = np.asarray(arrays["sigma0"], dtype=float)
    if sigma0.shape != (B, d, d):
        raise ValueError(f"sigma0: shape {sigma0.shape}, expected ({B}, {d}, {d}) for {B} bases of {d} weights")
    if not np.all(np.isfinite(sigma0)):
        raise ValueError("sigma0: contains NaN or inf")
    if not np.allclose(sigma0, np.swapaxes(sigma0, 1, 2), rtol=1e-9, atol=1e-15):
        raise ValueError("sigma0: a covariance is not symmetric")
    try:
        np.linalg.cholesky(sigma0)
    except np.linalg.LinAlgError as e:
        raise ValueError("sigma0: a covariance is not positive definite") from e
    pca = GoalFeatures.from_arrays({k[4:]: v for k, v in arrays.items() if k.startswith("pca_")})
    from drake_skill.perception.pcae import CODE_SIZE
    if pca.components_.shape[1] != CODE_SIZE or pca.n_components != config.goal_features.n_components:
        raise ValueError(f"pca_components: shape {pca.components_.shape} disagrees with {yaml_path.name} "
                         f"(goal_features.n_components = {config.goal_features.n_components}) and the "
                         f"{CODE_SIZE}-D PCAE code")
    pomrp_meta = meta.get("pomrp")
    if not isinstance(pomrp_meta, dict):
        raise ValueError(f"{json_path}: field 'pomrp' missing or not an object")
    pomrp = Pomrp.from_arrays({k[6:]: v for k, v in arrays.items() if k.startswith("pomrp_")},
                              pomrp_meta, prefix="pomrp_")
    if pomrp.n_features != pca.n_components:
        raise ValueError(f"pomrp_hmm_means: {pomrp.n_features} features per frame, but the PCA gives "
                         f"{pca.n_components}")
    if version == 1:
        config.pomrp.off_model.enabled = False  # not recorded before version 2 (see Skill.load)
    if config.pomrp.reward != pomrp.reward_kind:
        raise ValueError(f"pomrp.reward: {yaml_path.name} says {config.pomrp.reward!r} but the saved reward is "
                         f"{pomrp.reward_kind!r}; refit the skill")
    for name, saved in (("verdict", pomrp.verdict_config), ("off_model", pomrp.off_model_config),
                        ("progress", pomrp.progress_config)):
        if getattr(config.pomrp, name) != saved:
            raise ValueError(f"pomrp.{name}: {yaml_path.name} says {getattr(config.pomrp, name)} but the "
                             f"fitted reward in {json_path.name} uses {saved}")
    info = meta.get("info")
    if not isinstance(info, dict):
        raise ValueError(f"{json_path}: field 'info' missing or not an object")
    # Skills before version 4 held the fingers closed (0 m) in every execution.
    opening = 0.0
    if version >= 4:
        raw = np.asarray(arrays.get("gripper_opening", np.nan))
        if raw.shape != () or not np.isfinite(raw) or not 0.0 <= float(raw) <= 2 * FINGER_MAX:
            raise ValueError(f"gripper_opening: {raw.tolist()!r}, expected a finger opening in "
                             f"[0, {2 * FINGER_MAX}] m")
        opening = float(raw)
    return Skill(config, dmps, int(raw_index), sigma0, pca, pomrp, weights, info, opening)


def gripper_opening(demos: Sequence) -> float:
    """The finger opening [m] a skill commands throughout an execution.

    The action model is the 7-D hand pose (docs/method.md section 2); the
    thesis's skills keep the gripper as it is during the skill, so the
    opening is a constant of the skill: the median over the demonstrations
    of each one's median commanded opening (``gripper_100hz``). A
    demonstration without a gripper record counts as closed (0 m).
    """
    per_demo = []
    for i, demo in enumerate(demos):
        grip = getattr(demo, "gripper_100hz", None)
        if grip is None:
            per_demo.append(0.0)
            continue
        grip = np.asarray(grip, dtype=float)
        if grip.size == 0 or not np.all(np.isfinite(grip)):
            raise ValueError(f"demos[{i}].gripper_100hz: empty or not finite; record the demonstration again")
        per_demo.append(float(np.median(grip)))
    return float(np.clip(np.median(per_demo), 0.0, 2 * FINGER_MAX))


def check_demonstrations_meet_rule(demos: Sequence, spec) -> None:
    """Raises a one-line ValueError when no demonstration meets the skill's success rule: the goal
    model would learn, as the goal, an end the rule calls a failure (docs/skills.md). Demonstrations
    without a ground-truth final state (on the robot: NaN, or none) are not judged."""
    from drake_skill.station.success import judge_success

    rule = getattr(spec, "success", None)
    if rule is None or not getattr(rule, "joint", "") or not len(demos):
        return
    finals = [float("nan") if getattr(d, "final_object_state", None) is None else float(d.final_object_state)
              for d in demos]
    if not all(np.isfinite(finals)) or any(judge_success(v, rule) for v in finals):
        return
    side = f">= {rule.above:g}" if rule.above is not None else f"<= {rule.below:g}"
    names = ", ".join(str(getattr(d, "path", None) or f"demos[{i}]") for i, d in enumerate(demos))
    ends = ", ".join(f"{v:.4g}" for v in finals)
    raise ValueError(f"{names}: no demonstration meets the skill's success rule ({rule.joint} {side}; they end "
                     f"at {ends}): demonstrate the skill further, or correct 'success' in the skill file "
                     f"'{spec.name}' to what the demonstrations show")


def fit_skill(demos: Sequence, config: SkillConfig | None = None) -> Skill:
    """Fits a skill from demonstrations (objects with ``times``, ``X_OE``,
    ``object_points``, ``perception_valid``, e.g. ``drake_skill.demos.format.Demonstration``).
    """
    if config is None:
        config = default_skill_config(getattr(demos[0], "skill", "")) if len(demos) else SkillConfig()
    if len(demos) < 2:
        raise ValueError(f"demos: need at least 2 demonstrations of '{config.skill}', got {len(demos)}")
    if config.cloud_frame not in CLOUD_FRAMES:
        raise ValueError(f"config.cloud_frame: {config.cloud_frame!r}; expected one of {', '.join(CLOUD_FRAMES)}")
    for i, demo in enumerate(demos):
        if getattr(demo, "object_points", None) is None:
            raise ValueError(f"demos[{i}]: recorded without perception (no object_points); "
                             "record demonstrations with the camera on")
        if config.cloud_frame == "object" and getattr(demo, "X_WO_start", None) is None:
            raise ValueError(f"demos[{i}]: no perceived object pose (X_WO_start) to express its clouds in "
                             "(cloud_frame: object); record it with the camera on, or fit with cloud_frame: world")
        skill = getattr(demo, "skill", config.skill)
        name = getattr(demo, "path", None) or f"demos[{i}]"
        if skill != config.skill:
            raise ValueError(f"{name}: a '{skill}' demonstration given to fit '{config.skill}'")
        n = len(demo.times)
        k_min = int(config.pomrp.goal_model.n_states_min)
        if n < k_min:
            raise ValueError(f"{name}: {n} frames at 10 Hz, fewer than the goal model's smallest state count "
                             f"(pomrp.goal_model.n_states_min = {k_min}); record a longer demonstration "
                             "or lower n_states_min")

    check_demonstrations_meet_rule(demos, config.spec)
    fit, config, dmp_fit = _fit_action(demos, config)

    from drake_skill.perception.pcae import load_pcae
    weights = _pcae_path(config)
    encoder = load_pcae(weights)
    pca = GoalFeatures.from_config(config.goal_features)
    codes = [encode_sequence(encoder, d.object_points, d.perception_valid, f"demos[{i}].perception_valid",
                             X_WO=d.X_WO_start if config.cloud_frame == "object" else None)
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
        "dmp_fit": dmp_fit,
    }
    opening = config.spec.gripper_opening
    skill = Skill(config, fit.dmps, fit.initial_index, fit.sigma0, pca, pomrp, weights, info,
                  gripper_opening(demos) if opening is None else float(opening))
    skill._encoder = encoder
    return skill


def _demo_names(demos: Sequence) -> list[str]:
    """Each demonstration's file (its name in the recorded set), else ``demo i``."""
    names = []
    for i, d in enumerate(demos):
        meta = getattr(d, "metadata", None)
        name = getattr(d, "path", None) or (meta.get("file") if isinstance(meta, dict) else None)
        names.append(str(name) if name else f"demo {i}")
    return names


def _action_data(demos: Sequence, config: SkillConfig) -> tuple[list, list]:
    """Per demonstration, the ``(times, X_OE)`` the DMPs fit and the near-contact mask on those times."""
    if config.dmp_data not in DMP_DATA:
        raise ValueError(f"config.dmp_data: {config.dmp_data!r}; expected one of {', '.join(DMP_DATA)}")
    data, masks = [], []
    for name, d in zip(_demo_names(demos), demos):
        if config.dmp_data == "100hz":
            if getattr(d, "times_100hz", None) is None or getattr(d, "X_OE_100hz", None) is None:
                raise ValueError(f"{name}: no 100 Hz action data (times_100hz, X_OE_100hz); record it again "
                                 "or fit the 10 Hz samples with dmp_data: 10hz")
            data.append((d.times_100hz, d.X_OE_100hz))
        else:
            data.append((d.times, d.X_OE))
        state = getattr(d, "object_state_100hz", None)
        mask = np.zeros(len(data[-1][0]), dtype=bool)
        if state is not None and getattr(d, "times_100hz", None) is not None:
            full = contact_mask(d.times_100hz, state)
            mask = np.interp(data[-1][0], d.times_100hz, full.astype(float)) > 0.5
        masks.append(mask)
    return data, masks


def coarse_exploration_covariance(data: Sequence, config: DmpConfig, coarse: int, n_basis: int, *, seed: int,
                                  ridge: float) -> np.ndarray:
    """Sigma_b^0 (n_basis, d, d) for a fit with many bases, from fits with ``coarse`` bases.

    Thesis Eq. 5.3 takes Sigma_b^0 from the spread of the per-demonstration
    weights. With B chosen from a tolerance (60-100 bases), the demonstrations'
    fine-scale differences (each one's own controller ringing, measured at
    100 Hz) dominate that spread, and samples from it are wild: on a pushing
    skill of notebook 05 every exploratory rollout failed. The spread is
    therefore taken from fits with ``coarse`` bases (what the thesis
    explores) and carried to the fine bases: the weight of a normalised
    basis mixture is the forcing term near its centre, so block b is the
    coarse blocks linearly interpolated at fine basis b's centre time
    (both are equally spaced in time), times ``n_basis / coarse``, which
    keeps the path spread of a sample (a path integrates the forcing twice:
    its variance goes as sigma^2 / B for B independent weights).
    """
    coarse_fit = fit_demonstrations(data, dc.replace(config, n_basis=int(coarse)), seed=seed, ridge=ridge)
    u_fine = np.linspace(0.0, 1.0, int(n_basis))
    u_coarse = np.linspace(0.0, 1.0, int(coarse))
    blocks = coarse_fit.sigma0.reshape(int(coarse), -1)
    fine = np.stack([np.interp(u_fine, u_coarse, blocks[:, k]) for k in range(blocks.shape[1])], axis=1)
    d = coarse_fit.sigma0.shape[1]
    out = fine.reshape(int(n_basis), d, d) * (n_basis / coarse)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


#: The start offset fades out within this fraction of the time to the first contact.
START_JOIN_FRACTION = 0.8


def _start_join(data: Sequence, masks: Sequence) -> float:
    """``DmpConfig.start_join`` (a fraction of tau): START_JOIN_FRACTION of the earliest first
    contact over the demonstrations, each as a fraction of its duration (docs/method.md section
    2.1); 0 (the spring's transient) when none touches."""
    firsts = [float((t[m][0] - t[0]) / (t[-1] - t[0])) for (t, _), m in zip(data, masks) if np.any(m)]
    return round(START_JOIN_FRACTION * min(firsts), 4) if firsts else 0.0


def _fit_action(demos: Sequence, config: SkillConfig):
    """The DMP fits (docs/method.md section 2.2): B from the skill file or from the tolerance.

    Returns ``(DemonstrationFit, config with the fitted DmpConfig, report)``;
    the report (for skill.json and ``drake-skill fit``) holds B, how it was
    chosen, each demonstration's fit error and whether the tolerance is met.
    Raises ValueError when no B up to the cap meets the tolerance, naming
    the best error reached.
    """
    data, masks = _action_data(demos, config)
    names = _demo_names(demos)

    def fit_with(n_basis: int):
        f = fit_demonstrations(data, dc.replace(config.dmp, n_basis=int(n_basis)), seed=config.seed,
                               ridge=config.dmp_ridge)
        return f.dmps, f.config

    tolerance = config.dmp_tolerance
    fixed = config.spec.dmp_bases is not None
    shortest = min(len(t) for t, _ in data)
    if fixed or config.spec.name == "":
        n = int(config.dmp.n_basis)
        if n > shortest:
            raise ValueError(f"{names[int(np.argmin([len(t) for t, _ in data]))]}: {shortest} samples, fewer than "
                             f"the {n} DMP bases (dmp.n_basis); record a longer demonstration or use fewer bases")
        errors = None   # measured on the fit below, the only one made
        how = ("thesis Table 6.1 (fit: thesis)" if config.dmp_data == "10hz"
               else "fixed by the skill file (dmp_bases)")
    else:
        choice = choose_n_basis(fit_with, data, masks, tolerance)
        n, errors, met = choice.n_basis, choice.errors, choice.met
        if not met:
            worst = max(errors, key=lambda e: (e.contact_max_mm, e.rms_mm))
            who = names[errors.index(worst)]
            raise ValueError(
                f"{who}: no number of DMP bases up to {min(tolerance.max_bases, shortest)} fits it within "
                f"{tolerance.contact_max_mm:g} mm near contact and {tolerance.rms_mm:g} mm RMS (best: "
                f"{worst.contact_max_mm:.1f} mm near contact, {worst.rms_mm:.1f} mm RMS at B = {n}); record a "
                "longer, smoother demonstration, or set dmp_bases in the skill file to accept the error")
        how = "the fewest that meet the tolerance"
    join = _start_join(data, masks) if config.dmp_data != "10hz" else 0.0
    # Joined before contact, an unscaled path keeps the contact where it was shown; stretching
    # any column would move it (docs/method.md section 2.1).
    rule = "joined" if join > 0 and config.dmp.scale_rule == "span" else config.dmp.scale_rule
    fit = fit_demonstrations(data, dc.replace(config.dmp, n_basis=n, start_join=join, scale_rule=rule),
                             seed=config.seed, ridge=config.dmp_ridge)
    if errors is None:
        # Each DMP integrated from its own start: the join and the scaled columns do not change it.
        errors = [fit_errors(d, fit.config, t, p, m) for d, (t, p), m in zip(fit.dmps, data, masks)]
        met = all(tolerance.met_by(e) for e in errors)
    known = all(np.all(np.isfinite(getattr(d, "object_state_100hz", [np.nan]))) for d in demos)
    coarse = int(config.exploration_bases)
    if 0 < coarse < n:
        fit.sigma0 = coarse_exploration_covariance(data, dc.replace(config.dmp, start_join=join), coarse, n,
                                                   seed=config.seed, ridge=config.dmp_ridge)
    report = {"n_basis": n, "how": how, "data": config.dmp_data, "tolerance_met": bool(met),
              "exploration_bases": coarse if 0 < coarse < n else n,
              "object_state_known": bool(known),
              "tolerance": {"contact_max_mm": tolerance.contact_max_mm, "rms_mm": tolerance.rms_mm},
              "errors": [dict(e.as_dict(), demo=names[i]) for i, e in enumerate(errors)],
              "scaled": {str(k): v for k, v in fit.scale_reasons.items()}, "start_join": join}
    return fit, dc.replace(config, dmp=fit.config), report
