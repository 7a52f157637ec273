"""``report.html``: one self-contained page per run (scores with CIs, a plot, a row per episode).

Written at the end of every run. When the run was recorded, each episode row plays its
own segment of the dataset's videos (``<video src="dataset/videos/…mp4#t=from,to">``: the
merged dataset packs many episodes per file), so the report adds no video files of its own.
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path
from typing import Any

from molmo_lerobot.export.merge import DATASET_DIR, EVAL_EPISODES, EVAL_INFO, read_eval_records
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.runner.results import EpisodeResult

REPORT_FILE = "report.html"

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;margin:2rem;color:#222;max-width:1400px}
h1{font-size:1.4rem;margin-bottom:.2rem} h2{font-size:1.1rem;margin-top:2rem}
.sub{color:#666;margin-top:0} .big{font-size:2rem;font-weight:600}
table{border-collapse:collapse;font-size:.85rem} td,th{border-bottom:1px solid #ddd;padding:.3rem .6rem;text-align:left}
th{background:#f6f6f6} td.num{text-align:right;font-variant-numeric:tabular-nums}
.ok{color:#137333;font-weight:600} .fail{color:#b3261e} .err{color:#b3261e;font-size:.8rem;max-width:28rem}
video{width:192px;border-radius:3px;background:#000;margin-right:4px}
"""


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * float(x):.1f}%"


def _e(x: Any) -> str:
    return html.escape("" if x is None else str(x))


def _bars_svg(summary: dict[str, Any]) -> str:
    """Horizontal bars per task (and overall): success at the end and at any step, with 95% CI whiskers."""
    rows = [("all", summary)] + sorted((summary.get("per_task") or {}).items())
    left, width, bar, gap = 140, 420, 11, 10
    height = len(rows) * (2 * bar + gap) + 40
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + width + 60}" height="{height}" '
             'font-family="system-ui,sans-serif" font-size="11" role="img" aria-label="success rates">']
    for tick in (0, 0.25, 0.5, 0.75, 1.0):
        x = left + tick * width
        parts.append(f'<line x1="{x}" y1="10" x2="{x}" y2="{height - 25}" stroke="#e3e3e3"/>'
                     f'<text x="{x}" y="{height - 12}" text-anchor="middle" fill="#666">{int(tick * 100)}%</text>')
    y = 14.0
    for name, b in rows:
        parts.append(f'<text x="{left - 8}" y="{y + bar + 3}" text-anchor="end">{_e(name)} (n={b.get("n_episodes", 0)})</text>')
        for key, ci_key, color in (("success_rate", "ci95", "#1a73e8"), ("success_once_rate", "success_once_ci95", "#9bbcf3")):
            rate = float(b.get(key) or 0.0)  # null: no episode of this block simulated
            lo, hi = (list(b.get(ci_key) or (rate, rate)) + [0.0, 1.0])[:2]
            parts.append(f'<rect x="{left}" y="{y}" width="{rate * width:.1f}" height="{bar}" fill="{color}">'
                         f'<title>{_e(name)} {key}: {_pct(rate)} (95% CI {_pct(lo)}–{_pct(hi)})</title></rect>')
            cy = y + bar / 2
            parts.append(f'<line x1="{left + lo * width:.1f}" y1="{cy}" x2="{left + hi * width:.1f}" y2="{cy}" '
                         'stroke="#333" stroke-width="1.2"/>')
            for end in (lo, hi):
                parts.append(f'<line x1="{left + end * width:.1f}" y1="{cy - 3}" x2="{left + end * width:.1f}" '
                             f'y2="{cy + 3}" stroke="#333" stroke-width="1.2"/>')
            parts.append(f'<text x="{left + width + 6}" y="{y + bar - 2}" fill="#444">{_pct(rate)}</text>')
            y += bar
        y += gap
    legend_y = height - 4
    parts.append(f'<rect x="{left}" y="{legend_y - 8}" width="10" height="8" fill="#1a73e8"/>'
                 f'<text x="{left + 14}" y="{legend_y}">success at the end (primary)</text>'
                 f'<rect x="{left + 190}" y="{legend_y - 8}" width="10" height="8" fill="#9bbcf3"/>'
                 f'<text x="{left + 204}" y="{legend_y}">success at any step</text>')
    parts.append("</svg>")
    return "".join(parts)


def _task_table(summary: dict[str, Any]) -> str:
    rows = [("all", summary)] + sorted((summary.get("per_task") or {}).items())
    out = ["<table><tr><th>task</th><th>episodes</th><th>success (end)</th><th>95% CI</th>"
           "<th>success (any step)</th><th>95% CI</th><th>errors</th></tr>"]
    for name, b in rows:
        lo, hi = (list(b.get("ci95") or (None, None)) + [0, 1])[:2]
        lo2, hi2 = (list(b.get("success_once_ci95") or (None, None)) + [0, 1])[:2]
        out.append(f"<tr><td>{_e(name)}</td><td class=num>{b.get('n_episodes', 0)}</td>"
                   f"<td class=num>{_pct(b.get('success_rate', 0))}</td><td>{_pct(lo)} – {_pct(hi)}</td>"
                   f"<td class=num>{_pct(b.get('success_once_rate', 0))}</td><td>{_pct(lo2)} – {_pct(hi2)}</td>"
                   f"<td class=num>{b.get('n_errors', 0)}</td></tr>")
    out.append("</table>")
    return "".join(out)


def episode_videos(output_dir: Path) -> dict[int, list[tuple[str, str]]]:
    """benchmark episode index → [(camera, "relative/video.mp4#t=from,to")] from the recorded dataset."""
    root = Path(output_dir) / DATASET_DIR
    if not (root / EVAL_EPISODES).is_file():
        return {}
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    info = json.loads((root / EVAL_INFO).read_text())
    meta = LeRobotDatasetMetadata(info["repo_id"], root=root)
    out: dict[int, list[tuple[str, str]]] = {}
    for rec in read_eval_records(root):
        ep = rec.get("episode_index")
        if ep is None:
            continue
        row = meta.episodes[int(ep)]
        clips = []
        for key in meta.video_keys:
            rel = os.path.relpath(root / meta.get_video_file_path(int(ep), key), output_dir)
            t0, t1 = float(row[f"videos/{key}/from_timestamp"]), float(row[f"videos/{key}/to_timestamp"])
            clips.append((key.rsplit(".", 1)[-1], f"{rel}#t={t0:.3f},{t1:.3f}"))
        out[int(rec["benchmark_episode_index"])] = clips
    return out


def _episode_rows(results: list[EpisodeResult], videos: dict[int, list[tuple[str, str]]]) -> str:
    head = ("<table><tr><th>#</th><th>house</th><th>task</th><th>instruction</th><th>success</th>"
            "<th>any step</th><th>steps</th><th>seed</th><th>time</th><th>video</th></tr>")
    out = [head]
    for r in sorted(results, key=lambda r: r.episode_index):
        if r.error is not None:
            status = f'<span class="fail">error</span><div class="err">{_e(r.error)}</div>'
        else:
            status = '<span class="ok">yes</span>' if r.success else '<span class="fail">no</span>'
        clips = "".join(f'<video src="{_e(src)}" title="{_e(cam)}" controls muted preload="metadata"></video>'
                        for cam, src in videos.get(r.episode_index, []))
        out.append(
            f"<tr><td class=num>{r.episode_index}</td><td class=num>{_e(r.house_index)}</td>"
            f"<td>{_e(r.task_type or r.task_cls)}</td><td>{_e(r.prompt)}</td><td>{status}</td>"
            f"<td>{'yes' if r.success_once else 'no'}</td><td class=num>{r.steps}</td><td class=num>{r.seed}</td>"
            f"<td class=num>{r.duration_s:.1f}s</td><td>{clips}</td></tr>")
    out.append("</table>")
    return "".join(out)


def render_report(summary: dict[str, Any], results: list[EpisodeResult],
                  videos: dict[int, list[tuple[str, str]]] | None = None) -> str:
    """The report page as a string (no I/O)."""
    bench = summary.get("benchmark") or {}
    policy = summary.get("policy") or {}
    policy_name = policy.get("name", "?") if isinstance(policy, dict) else str(policy)
    lo, hi = (list(summary.get("ci95") or (None, None)) + [0, 1])[:2]
    title = f"{policy_name} on {bench.get('name', '?')}"
    versions = ", ".join(f"{k} {v}" for k, v in (summary.get("versions") or {}).items())
    return "".join([
        "<!doctype html><html lang=en><head><meta charset=utf-8>",
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1><p class=sub>benchmark sha256 <code>{_e(str(bench.get('sha256', ''))[:16])}</code> · "
        f"seed {_e(summary.get('seed'))} · {summary.get('n_episodes', 0)} episodes "
        f"({summary.get('n_errors', 0)} errors) · {_e(summary.get('started_at', ''))}</p>",
        f"<p><span class=big>{_pct(summary.get('success_rate', 0))}</span> success at the end "
        f"(95% CI {_pct(lo)} – {_pct(hi)}) · {_pct(summary.get('success_once_rate', 0))} at any step · "
        f"{summary.get('n_success', 0)}/{summary.get('n_episodes', 0)}</p>",
        f"<p class=sub>{_e(summary.get('primary_metric', ''))}. Errored episodes count as failures.</p>",
        "<h2>Per task</h2>", _task_table(summary), "<div style='margin-top:1rem'>", _bars_svg(summary), "</div>",
        "<h2>Episodes</h2>", _episode_rows(results, videos or {}),
        f"<p class=sub style='margin-top:2rem'>{_e(versions)}</p></body></html>\n",
    ])


def write_report(output_dir: Path | str, summary: dict[str, Any], results: list[EpisodeResult]) -> Path:
    """Write ``output_dir/report.html`` (atomically) and return its path."""
    output_dir = Path(output_dir)
    page = render_report(summary, results, episode_videos(output_dir))
    path = output_dir / REPORT_FILE
    return atomic_write(path, page)
