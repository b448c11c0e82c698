"""A learn run's ``report.html``: one self-contained page (images inline, no server) of what happened.

Sections, from the run's files:

1. the numbers of ``summary.json`` (held-out success before and after, which
   policy was returned, the reflex rate, and in simulation the learned
   reward's quality: ``reward_auc``, ``verdict_fpr``, ``verdict_fnr``);
2. ``learning_curve.png``;
3. in simulation, ``return_vs_state.png`` (docs/method.md section 3) and the
   rollouts the reward ranked worst against the truth: the highest-return
   failures and the lowest-return successes, each with its last camera frame
   (``rollouts/``, :mod:`~drake_skill.learning.rollout_store`) and the
   ``drake-skill replay`` command that shows it;
4. the rollouts the reflex stopped: when, what touched what, the last frame.

Panels that need the ground truth appear only where the records have it (a
robot run has none).
"""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from drake_skill.fileio import atomic_write_text, png_data_url
from drake_skill.learning.rollout_store import load_rollout, rollouts_path

__all__ = ["WORST", "worst_ranked", "write_run_report"]

#: How many of the highest-return failures and of the lowest-return successes the report shows.
WORST = 3

_STYLE = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}
figure{display:inline-block;margin:.4em;vertical-align:top;font-size:.85em}figure img{image-rendering:pixelated;
width:213px;border:1px solid #999}code{background:#f3f3f3;padding:0 .2em}"""


def worst_ranked(records: Sequence[Mapping[str, Any]], n: int = WORST) -> tuple[list[dict], list[dict]]:
    """(the ``n`` highest-return ground-truth failures, the ``n`` lowest-return successes) among the
    rollout records that ran to their end and have a ground truth (return = the record's ``reward``)."""
    judged = [dict(r) for r in records if r.get("type") == "rollout" and not r.get("failed")
              and r.get("final_object_state") is not None]
    failures = sorted((r for r in judged if not r["success"]), key=lambda r: -r["reward"])[:n]
    successes = sorted((r for r in judged if r["success"]), key=lambda r: r["reward"])[:n]
    return failures, successes


def _file_img(path: Path) -> str:
    if not path.is_file():
        return ""
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<p><img alt="{html.escape(path.name)}" src="data:image/png;base64,{data}"></p>'


def _last_frame(out_dir: Path, record: Mapping) -> np.ndarray | None:
    try:
        kept = load_rollout(rollouts_path(out_dir, f"episode_{int(record['episode']):03d}"), int(record["index"]))
    except (OSError, ValueError, KeyError):
        return None
    return kept.get("last_frame")


def _figure(out_dir: Path, record: Mapping, caption: str) -> str:
    frame = _last_frame(out_dir, record)
    kept = frame is not None and frame.size
    img = f'<img alt="last frame" src="{png_data_url(frame)}">' if kept else "(no frame kept)"
    command = f"drake-skill replay {out_dir} --episode {record['episode']} --index {record['index']}"
    return (f"<figure>{img}<figcaption>episode {record['episode']}, rollout {record['index']}<br>"
            f"{html.escape(caption)}<br><code>{html.escape(command)}</code></figcaption></figure>")


def _number(value) -> str:
    if value is None:
        return "-"
    return f"{value:.3g}" if isinstance(value, float) else html.escape(str(value))


def _summary_table(summary: Mapping) -> str:
    keys = ("held_out_before", "held_out_after", "selected_episode", "reflex_rate", "reward_auc",
            "verdict_fpr", "verdict_fnr", "n_rollouts")
    rows = "".join(f"<tr><th>{k}</th><td>{_number(summary.get(k))}</td></tr>" for k in keys if k in summary)
    return f"<table>{rows}</table>"


def _worst_section(out_dir: Path, records) -> str:
    failures, successes = worst_ranked(records)
    if not failures and not successes:
        return "<p>No rollout ran to its end with a ground truth to rank it against.</p>"
    parts = ["<h3>Failures the reward rated highest</h3>"]
    parts += [_figure(out_dir, r, f"return {r['reward']:.1f}, final state {r['final_object_state']:.4g}, "
                                  f"verdict {'success' if r['verdict'] else 'failure'}") for r in failures] or ["-"]
    parts.append("<h3>Successes the reward rated lowest</h3>")
    parts += [_figure(out_dir, r, f"return {r['reward']:.1f}, final state {r['final_object_state']:.4g}, "
                                  f"verdict {'success' if r['verdict'] else 'failure'}") for r in successes] or ["-"]
    return "".join(parts)


def _trip_caption(record: Mapping) -> str:
    contact = record.get("contact") or {}
    pairs = "; ".join(f"{a} - {b} {f:.0f} N" for a, b, f in contact.get("pairs") or []) or "contacts not reported"
    return f"t = {contact.get('t', '?')} s, {contact.get('cause', '')}: {pairs}"


def _trips_section(out_dir: Path, records) -> str:
    trips = [r for r in records if r.get("type") == "rollout" and r.get("reason") == "reflex"]
    if not trips:
        return "<p>None.</p>"
    return f"<p>{len(trips)} rollouts.</p>" + "".join(_figure(out_dir, r, _trip_caption(r)) for r in trips)


def write_run_report(out_dir, records: Sequence[Mapping[str, Any]], summary: Mapping[str, Any]) -> Path:
    """Writes ``out_dir/report.html`` (module docstring) from the run's ``records`` (results.jsonl's),
    ``summary`` (summary.json's) and the figures and ``rollouts/`` already in ``out_dir``."""
    out_dir = Path(out_dir)
    title = f"{summary.get('skill', '')}: {summary.get('method', '')}, {summary.get('reward', '')} reward"
    truth = any(r.get("type") == "rollout" and r.get("final_object_state") is not None for r in records)
    body = [f"<h1>{html.escape(title)}</h1>", _summary_table(summary), "<h2>Learning curve</h2>",
            _file_img(out_dir / "learning_curve.png")]
    if truth:
        body += ["<h2>The learned return against the object's final state</h2>",
                 _file_img(out_dir / "return_vs_state.png"),
                 "<h2>Rollouts the reward ranked worst against the truth</h2>", _worst_section(out_dir, records)]
    body += ["<h2>Rollouts the reflex stopped</h2>", _trips_section(out_dir, records)]
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head><body>{''.join(body)}</body></html>\n")
    return atomic_write_text(out_dir / "report.html", page)
