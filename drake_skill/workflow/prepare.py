"""A fitted skill for a learning run: given, fitted from demonstrations, or recorded and fitted.

``drake-skill learn`` and the chapter-7 grid (``drake_skill.experiments.grid``)
both start here; the fit prints what ``drake-skill fit`` prints.
"""

from __future__ import annotations

import dataclasses as dc
import sys
from pathlib import Path
from typing import Callable

from drake_skill import inputs

__all__ = ["PrepareConfig", "fit_and_refine_report", "prepare_skill", "print_fit_report"]


@dc.dataclass
class PrepareConfig:
    """Where a learning run's skill comes from.

    skill: a shipped skill's name or a skill file (or None: the skill the
    demonstrations or ``skill_dir`` name). skill_dir: a fitted skill to use
    as it is. demos: a folder of demo_*.npz files to fit from (neither
    ``skill_dir`` nor ``demos``: scripted demonstrations are recorded).
    station_for: ``station_for(spec) -> Scenario``, the scenario to
    record and refine on for the skill once it is known (it may come from the
    demonstrations); None: the skill's own. fit: "tolerance" or "thesis"
    (docs/method.md 2.2). quiet: no progress bars.
    """

    skill: str | None = None
    skill_dir: Path | None = None
    demos: Path | None = None
    station_for: Callable | None = None
    fit: str = "tolerance"
    quiet: bool = False


def print_fit_report(lines: list[str], warnings: list[str]) -> None:
    """The fit's lines on stdout, each warning as one ``drake-skill: warning:`` line on stderr."""
    print("\n".join(lines))
    for message in warnings:
        print(f"drake-skill: warning: {message}", file=sys.stderr)


def fit_and_refine_report(skill, demos, station_config=None) -> tuple[list[str], list[str]]:
    """Refines the freshly fitted ``skill`` (``SkillConfig.dmp_refine``) and returns the lines and
    warnings that say what the fit chose and how closely each DMP follows its demonstration."""
    from drake_skill.learning.refine import refine_skill, refinement_lines

    lines, warnings = skill.fit_report()
    if skill.config.dmp_refine > 0 and skill.config.dmp_data == "100hz":
        print(f"refining the DMPs on the simulated station ({len(demos)} imitations x "
              f"{skill.config.dmp_refine + 1}) ...")
        more, warned = refinement_lines(refine_skill(skill, demos, station_config))
        lines, warnings = lines + more, warnings + warned
    return lines, warnings


def _given(config: PrepareConfig, spec) -> Path:
    from drake_skill.fitted_skill import Skill

    skill = Skill.load(config.skill_dir)      # errors name the file
    if spec is not None and spec.name != skill.name:
        raise ValueError(f"--skill {config.skill} but {config.skill_dir} holds a '{skill.name}' skill")
    return config.skill_dir


def _user_demos(config: PrepareConfig, spec):
    """(spec, demos) of ``config.demos``."""
    from drake_skill.demos.format import load_demonstrations

    demos = load_demonstrations(config.demos)
    if not demos:
        raise FileNotFoundError(f"{config.demos}: no demo_*.npz files; record some with 'drake-skill demos record'")
    name = demos[0].skill
    if spec is not None and spec.name != name:
        raise ValueError(f"--skill {config.skill} but {config.demos} holds '{name}' demonstrations")
    if spec is None:
        spec = inputs.skill(name, f"--demos {config.demos} (skill '{name}'; give its skill file as --skill)")
    return spec, demos


def _scripted_demos(config: PrepareConfig, spec, station, folder: Path):
    from drake_skill.demos.demonstrator import ScriptedDemonstrator
    from drake_skill.demos.format import save_demonstrations

    if spec is None:
        raise ValueError("--skill: missing; name the skill to learn (a shipped skill: drake-skill skills, "
                         "or a skill file), or give --skill-dir or --demos")
    print(f"recording scripted demonstrations of '{spec.name}' into {folder} ...")
    demos = ScriptedDemonstrator(spec, station_config=station).record_many(progress=not config.quiet)
    save_demonstrations(demos, folder, force=True)
    return demos


def prepare_skill(config: PrepareConfig, out: Path) -> Path:
    """The fitted skill's folder: ``config.skill_dir``; or ``OUT/initial_skill``, fitted from
    ``config.demos`` or from scripted demonstrations recorded into ``OUT/demos`` (a fit already
    there from recorded demonstrations is used again, so a resumed run fits once)."""
    from drake_skill.learning.evaluation import save_fitted_skill
    from drake_skill.fitted_skill import Skill, default_skill_config, fit_skill
    from drake_skill.skills import scenario_for_skill

    if config.skill_dir is not None and config.demos is not None:
        raise ValueError("give --skill-dir or --demos, not both")
    out = Path(out)
    spec = inputs.skill(config.skill) if config.skill is not None else None
    if config.skill_dir is not None:
        return _given(config, spec)
    initial = out / "initial_skill"
    if (initial / "skill.json").is_file() and config.demos is None:
        skill = Skill.load(initial)
        if spec is not None and spec.name != skill.name:
            raise ValueError(f"{initial} holds a '{skill.name}' skill, not '{spec.name}'; use another --out")
        print(f"using the skill fitted earlier: {initial}")
        return initial
    if config.demos is not None:
        spec, demos = _user_demos(config, spec)
    station_for = config.station_for if config.station_for is not None else scenario_for_skill
    station = station_for(spec) if spec is not None else None
    if config.demos is None:
        demos = _scripted_demos(config, spec, station, out / "demos")
    print(f"fitting '{spec.name}' from {len(demos)} demonstrations ...")
    skill = fit_skill(demos, default_skill_config(spec, fit=config.fit))
    print_fit_report(*fit_and_refine_report(skill, demos, station))
    skill = save_fitted_skill(skill, initial, overwrite=True, station_config=station, progress=not config.quiet)
    print(skill.summary())
    return initial
