"""How closely a skill's plain imitation repeats each of its demonstrations.

``drake-skill bench imitation [--json]`` / ``python tools/bench_imitation.py [--json]``.

For each demonstration of a skill, its DMP (``drake_skill.fitted_skill.fit_skill``
with the skill file's defaults and, as ``drake-skill fit`` does, the
refinement on the simulated station unless --no-refine; or a fitted
skill's) is integrated alone and
executed in the simulated station on the demonstration's own object pose
(``drake_skill.learning.imitation.imitate``: ground-truth object frame, no
perception, 100 Hz records). Figures (position only; mm unless said):

  fit_max_mm, fit_rms_mm        the DMP integrated alone vs the demonstration's
                                recorded hand path (X_OE_100hz), max and RMS
  tracking_max_mm, _rms_mm      the imitation's measured hand path vs the DMP's
                                commanded path (the controller's lag and sag)
  total_max_mm, total_rms_mm    the imitation's measured path vs the
                                demonstration's recorded path, sample by
                                sample, no time alignment
  contact_max_mm                the same, max over the samples "near contact":
                                where the demonstrated object moves
                                (|d state/dt| > 2 % of its peak, dilated by
                                0.2 s either side)
  lag_ms                        the time shift that best aligns the imitation's
                                measured path with the demonstration's (least
                                squares over 10 ms shifts, refined by a
                                parabola); > 0: the imitation runs behind
  object_state_demo, _imitation the object's joint at the end (rad or m);
  object_state_error            and their absolute difference
  reflex_trips                  1 when the collision reflex stopped the
                                imitation (failed / reason say why it stopped)
  contact_shift_mm              how far the near-contact part of the DMP's path
                                moves in the object frame when its start moves
                                by +-5 cm along x and along y of the object
                                frame (integrated alone, same goal), max
  contact_samples               how many samples are near contact
  refined                       the DMP is the refined one (fit_* then compare
                                the refined DMP, which commands an offset path,
                                with the demonstration); null: no refinement

Per skill, ``bases`` is the DMP's number of basis functions and ``worst``
each figure's maximum over the demonstrations (lag_ms: the largest |lag|;
figures without a value, e.g. near contact for an object that never moves,
are left out of the maximum and are null). Output with --json::

  {"skills": {"<name>": {"bases": B, "demos": [{"demo": file, "seed": s, ...}],
                         "worst": {"fit_rms_mm": x, "fit_max_mm": x, "tracking_rms_mm": x,
                                   "total_rms_mm": x, "total_max_mm": x, "contact_max_mm": x,
                                   "lag_ms": x, "object_state_error": x, "reflex_trips": n,
                                   "contact_shift_mm": x}}}}

Which demonstrations:

  (default)                    every shipped skill: its scripted demonstrations
                               recorded into a temporary folder (the code of
                               'drake-skill demos record'), then fitted
  --skills open close          only these shipped skills
  --skill FILE_OR_NAME         one skill file's scripted demonstrations
  --demos DIR                  reuse recorded demonstrations instead of recording:
                               a folder of demo_*.npz (one skill), or a folder
                               holding one such folder per skill name
  --demos DIR --skill FILE     a user's own demonstrations of a skill file, fitted here
  --skill-dir DIR [--demos D]  a fitted skill (drake-skill fit / learn) and the
                               demonstrations it was fitted from (default: DIR/demos
                               or DIR/../demos, as drake-skill learn lays them out)

A progress line per demonstration goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

#: The figures of ``worst``, in the order printed.
WORST_KEYS = ("fit_rms_mm", "fit_max_mm", "tracking_rms_mm", "total_rms_mm", "total_max_mm", "contact_max_mm",
              "lag_ms", "object_state_error", "reflex_trips", "contact_shift_mm")


def _progress(message: str, quiet: bool = False) -> None:
    if not quiet:
        print(message, file=sys.stderr, flush=True)


def _rounded(value):
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    value = float(value)
    return round(value, 4) if math.isfinite(value) else None


def worst_of(rows: list[dict]) -> dict:
    """Each :data:`WORST_KEYS` figure's maximum over ``rows`` (lag: the largest |lag|); None where none has one."""
    from drake_skill.action.metrics import nan_max

    worst = {}
    for key in WORST_KEYS:
        values = [row.get(key) for row in rows]
        if key == "lag_ms":
            values = [None if v is None else abs(v) for v in values]
        best = nan_max(values)
        worst[key] = int(best) if key == "reflex_trips" and best is not None else _rounded(best)
    return worst


# ------------------------------------------------------------------ demonstrations
def _has_demos(folder: Path) -> bool:
    return folder.is_dir() and any(folder.glob("demo_*.npz"))


def _demo_folder(root: Path, name: str) -> Path:
    """The folder of ``name``'s demonstrations under ``--demos root`` (root itself or root/name)."""
    if _has_demos(root / name):
        return root / name
    if _has_demos(root):
        return root
    raise FileNotFoundError(f"--demos {root}: no demo_*.npz files for '{name}' there or in {root / name}; "
                            f"record them with 'drake-skill demos record --skill {name} --out {root / name}'")


def _load_demos(folder: Path, name: str, count: int):
    from drake_skill.demos.format import load_demonstrations

    demos = load_demonstrations(folder)
    if demos[0].skill != name:
        raise ValueError(f"--demos {folder}: holds '{demos[0].skill}' demonstrations, not '{name}'; give the "
                         f"folder of '{name}' or its skill file as --skill")
    return demos[:count] if count else demos


def _record(spec, count: int, seed: int, folder: Path, quiet: bool):
    """Scripted demonstrations of ``spec`` recorded and saved as 'drake-skill demos record' does."""
    import dataclasses as dc

    from drake_skill.demos.demonstrator import DemonstratorConfig, ScriptedDemonstrator
    from drake_skill.demos.format import load_demonstrations, save_demonstrations

    config = DemonstratorConfig()
    config = dc.replace(config, count=count or config.count or int(spec.demonstrations), seed=seed)
    _progress(f"{spec.name}: recording {config.count} scripted demonstrations into {folder} ...", quiet)
    demos = ScriptedDemonstrator(spec, config).record_many(progress=False)
    save_demonstrations(demos, folder, force=True)
    return load_demonstrations(folder)


# ------------------------------------------------------------------ one skill
def bench_skill(skill, demos, quiet: bool = False, shift_m: float = 0.05) -> dict:
    """``{"bases", "demos", "worst"}`` of one fitted skill over ``demos`` (its DMPs in the same order)."""
    from drake_skill.learning.imitation import Imitator, imitation_metrics

    imitator = Imitator(skill)
    config = skill.config.dmp
    rows = []
    for i, demo in enumerate(demos):
        dmp = skill.dmps[i]
        imitation = imitator.imitate(dmp, demo)
        figures = imitation_metrics(config, dmp, demo, imitation, shift_m=shift_m)
        row = {"demo": imitation.demo, "seed": int(demo.seed), "refined": _refined(skill, i)}
        row.update({k: _rounded(v) for k, v in figures.items()})
        rows.append(row)
        stop = f"stopped: {imitation.reason}" if imitation.failed else "ran through"
        _progress(f"{skill.name} {row['demo']}: fit {_fmt(row['fit_rms_mm'])} mm RMS, total "
                  f"{_fmt(row['total_rms_mm'])} mm RMS ({_fmt(row['contact_max_mm'])} max near contact), lag "
                  f"{_fmt(row['lag_ms'])} ms, object {_fmt(row['object_state_imitation'], 3)} vs "
                  f"{_fmt(row['object_state_demo'], 3)}, {stop} ({imitation.wall_s:.1f} s)", quiet)
    return {"bases": int(config.n_basis), "demos": rows, "worst": worst_of(rows)}


def _refined(skill, i: int):
    """Whether DMP ``i`` is the refined one (``drake-skill fit``'s refinement); None for a plain fit."""
    report = skill.info.get("dmp_refinement") if isinstance(getattr(skill, "info", None), dict) else None
    if not report or i >= len(report):
        return None
    return not bool(report[i].get("kept_plain", True))


def _fit(spec, demos, quiet: bool, refine: bool = True):
    """``fit_skill`` with the skill file's defaults, then, as ``drake-skill fit`` does, the refinement
    on the simulated station when the config asks for it (``SkillConfig.dmp_refine``) and ``refine``."""
    from drake_skill.fitted_skill import default_skill_config, fit_skill

    _progress(f"{spec.name}: fitting {len(demos)} demonstrations ...", quiet)
    skill = fit_skill(demos, default_skill_config(spec))
    if refine and int(getattr(skill.config, "dmp_refine", 0)) > 0:
        from drake_skill.learning.refine import refine_skill

        _progress(f"{spec.name}: refining the DMPs on the simulated station ...", quiet)
        refine_skill(skill, demos)
    return skill


def run(args) -> dict:
    """The JSON object of the benchmark (module docstring) for parsed ``args``."""
    from drake_skill import inputs as errors
    from drake_skill.learning.imitation import check_demo_pairs

    out = {}
    if args.count and args.count < 2:
        raise ValueError(f"--count {args.count}: a skill is fitted from at least 2 demonstrations")
    if args.skill_dir is not None:
        from drake_skill.fitted_skill import Skill

        errors.input_folder(args.skill_dir, "--skill-dir", "a fitted skill (drake-skill fit)")
        skill = Skill.load(args.skill_dir)
        if args.demos is not None:
            folder = _demo_folder(args.demos, skill.name)
        else:
            candidates = [args.skill_dir / "demos", args.skill_dir.parent / "demos"]
            folder = next((c for c in candidates if _has_demos(c)), None)
            if folder is None:
                raise FileNotFoundError(f"--skill-dir {args.skill_dir}: no demonstrations in "
                                        f"{' or '.join(map(str, candidates))}; give the folder the skill was "
                                        "fitted from as --demos")
        demos = _load_demos(folder, skill.name, 0)
        check_demo_pairs(skill, demos, f"--demos {folder}")
        demos = demos[:args.count] if args.count else demos
        out[skill.name] = bench_skill(skill, demos, args.quiet, args.shift)
        return {"skills": out}
    if args.skill is not None:
        specs = [errors.skill(args.skill)]
    else:
        from drake_skill.skills import shipped_skill_names

        names = args.skills or shipped_skill_names()
        unknown = sorted(set(names) - set(shipped_skill_names()))
        if unknown:
            raise ValueError(f"--skills: {', '.join(unknown)} not shipped; choose from "
                             f"{', '.join(shipped_skill_names())} (or give a skill file as --skill)")
        specs = [errors.skill(name) for name in names]
    if args.demos is not None:
        errors.input_folder(args.demos, "--demos", "demo_*.npz files (drake-skill demos record)")
    with tempfile.TemporaryDirectory(prefix="bench_imitation_") as tmp:
        for spec in specs:
            if args.demos is not None:
                demos = _load_demos(_demo_folder(args.demos, spec.name), spec.name, args.count)
            else:
                demos = _record(spec, args.count, args.seed, Path(tmp) / spec.name, args.quiet)
            skill = _fit(spec, demos, args.quiet, refine=not args.no_refine)
            out[spec.name] = bench_skill(skill, demos, args.quiet, args.shift)
    return {"skills": out}


# ------------------------------------------------------------------ output
def _fmt(value, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


_COLUMNS = (("demo", "demo", 14, None), ("fit max/rms", ("fit_max_mm", "fit_rms_mm"), 13, 1),
            ("track max/rms", ("tracking_max_mm", "tracking_rms_mm"), 14, 1),
            ("total max/rms", ("total_max_mm", "total_rms_mm"), 14, 1), ("contact", "contact_max_mm", 8, 1),
            ("lag ms", "lag_ms", 7, 1), ("object demo/imit", ("object_state_demo", "object_state_imitation"), 17, 3),
            ("reflex", "reflex_trips", 7, 0), ("shift", "contact_shift_mm", 7, 1))


def _cell(row: dict, key, digits) -> str:
    if digits is None:
        return str(row.get(key, ""))
    if isinstance(key, tuple):
        return "/".join(_fmt(row.get(k), digits) for k in key)
    return _fmt(row.get(key), digits)


def table(result: dict) -> str:
    """The readable table: one row per demonstration and the worst per skill (mm, ms, rad or m)."""
    lines = []
    header = "".join(f"{title:>{width}}" if i else f"{title:<{width}}"
                     for i, (title, _, width, _) in enumerate(_COLUMNS))
    for name, entry in result["skills"].items():
        lines.append(f"{name}: B = {entry['bases']} bases, {len(entry['demos'])} demonstrations "
                     "(errors in mm, lag in ms, object state in rad or m)")
        lines.append("  " + header)
        for row in entry["demos"]:
            lines.append("  " + "".join(f"{_cell(row, key, d):>{w}}" if i else f"{_cell(row, key, d):<{w}}"
                                        for i, (_, key, w, d) in enumerate(_COLUMNS)))
        w = entry["worst"]
        lines.append(f"  worst: fit {_fmt(w['fit_max_mm'])}/{_fmt(w['fit_rms_mm'])}, tracking RMS "
                     f"{_fmt(w['tracking_rms_mm'])}, total {_fmt(w['total_max_mm'])}/{_fmt(w['total_rms_mm'])}, "
                     f"near contact {_fmt(w['contact_max_mm'])}, |lag| {_fmt(w['lag_ms'])} ms, object state "
                     f"error {_fmt(w['object_state_error'], 3)}, reflex trips {w['reflex_trips']}, contact shift "
                     f"{_fmt(w['contact_shift_mm'])}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="drake-skill bench imitation", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter, allow_abbrev=False)
    parser.add_argument("--json", action="store_true", help="print one JSON object (module description)")
    parser.add_argument("--skills", nargs="+", metavar="NAME",
                        help="only these shipped skills (default: every shipped skill)")
    parser.add_argument("--skill", metavar="FILE_OR_NAME",
                        help="one skill: a skill file or a shipped skill's name (its scripted demonstrations, "
                             "or those of --demos)")
    parser.add_argument("--demos", type=Path, metavar="DIR",
                        help="recorded demonstrations to use instead of recording: a folder of demo_*.npz, "
                             "or one folder per skill name in DIR")
    parser.add_argument("--skill-dir", type=Path, metavar="DIR",
                        help="a fitted skill (its DMPs and number of bases); demonstrations from --demos, "
                             "DIR/demos or DIR/../demos")
    parser.add_argument("--count", type=int, default=0,
                        help="demonstrations per skill (recorded, or the first of --demos; default: the skill "
                             "file's count / all)")
    parser.add_argument("--seed", type=int, default=0, help="first seed of the recorded demonstrations (default 0)")
    parser.add_argument("--shift", type=float, default=0.05, metavar="M",
                        help="start shift of contact_shift_mm, m (default 0.05)")
    parser.add_argument("--no-refine", action="store_true",
                        help="imitate the plain fit: leave out the refinement on the simulated station that "
                             "'drake-skill fit' applies (SkillConfig.dmp_refine)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.skill_dir is not None and (args.skill is not None or args.skills):
        parser.error("--skill-dir takes its skill from the folder; leave out --skill and --skills")
    if args.skill is not None and args.skills:
        parser.error("give either --skill (one skill file) or --skills (shipped skills)")
    if not (math.isfinite(args.shift) and args.shift > 0):
        parser.error(f"--shift {args.shift}: expected a distance > 0 m")
    start = time.perf_counter()
    result = run(args)
    if args.json:
        print(json.dumps(result))
    else:
        print(table(result))
        _progress(f"({time.perf_counter() - start:.0f} s)", args.quiet)
    return 0


if __name__ == "__main__":
    sys.exit(main())
