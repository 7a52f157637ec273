"""``report.html``: one self-contained page per run.

Scores with CIs and a plot, per task with its instruction and rewards (``avg_max_reward``,
``avg_sum_reward``); failure reasons grouped with counts; success per object category and per house
(where the episodes have them); the distribution of the time to first success; one row per episode
with a readable task label, a thumbnail (first | last exterior frame, saved by
:mod:`molmo_lerobot.export.glance` during the rollout) and a filter to failures or errors.

Written at the end of every run. When the run was recorded, each episode row plays its
own segment of the dataset's videos (``<video src="dataset/videos/…mp4#t=from,to">``: the
merged dataset packs many episodes per file), so the report adds no video files of its own.
"""

from __future__ import annotations

import html
import json
import os
import re
from pathlib import Path
from typing import Any

from molmo_lerobot.export.merge import DATASET_DIR, EVAL_EPISODES, EVAL_INFO, read_eval_records
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.results import SUCCESS_LABELS, EpisodeResult, Rates, RunSummary, TaskRates, wilson_ci

REPORT_FILE = "report.html"

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;margin:2rem;color:#222;max-width:1400px}
h1{font-size:1.4rem;margin-bottom:.2rem} h2{font-size:1.1rem;margin-top:2rem}
.sub{color:#666;margin-top:0} .big{font-size:2rem;font-weight:600}
table{border-collapse:collapse;font-size:.85rem} td,th{border-bottom:1px solid #ddd;padding:.3rem .6rem;text-align:left}
th{background:#f6f6f6} td.num{text-align:right;font-variant-numeric:tabular-nums}
.ok{color:#137333;font-weight:600} .fail{color:#b3261e} .err{color:#b3261e;font-size:.8rem;max-width:28rem}
video{width:192px;border-radius:3px;background:#000;margin-right:4px}
h3{font-size:.95rem;margin:.6rem 0 .3rem} .cols{display:flex;gap:2.5rem;flex-wrap:wrap;align-items:flex-start}
.grp{max-height:24rem;overflow-y:auto;display:block}
.bar{display:inline-block;height:8px;background:#1a73e8;vertical-align:middle}
td.which{max-width:34rem;font-size:.8rem}
a.tag{font-size:.75rem;color:#b3261e;text-decoration:none;border:1px solid #e8b4b0;border-radius:3px;padding:0 3px}
#episodes img{height:64px;border-radius:3px;display:block} .filter label{margin-right:1rem}
"""


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * float(x):.1f}%"


def _e(x: Any) -> str:
    return html.escape("" if x is None else str(x))


def _rows(summary: RunSummary) -> list[tuple[str, Rates]]:
    return [("all", summary), *sorted(summary.per_task.items())]


def _bars_svg(summary: RunSummary) -> str:
    """Horizontal bars per task (and overall): success at the end and at any chunk end, with 95% CI whiskers."""
    rows = _rows(summary)
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
        parts.append(f'<text x="{left - 8}" y="{y + bar + 3}" text-anchor="end">'
                     f'{_e(name)} (n={b.n_episodes})</text>')
        for key, value, ci, color in (("success_rate", b.success_rate, b.ci95, "#1a73e8"),
                                      ("success_once_rate", b.success_once_rate, b.success_once_ci95, "#9bbcf3")):
            rate = float(value or 0.0)  # null: no episode of this block simulated
            lo, hi = ci or (rate, rate)
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
                 f'<text x="{left + 204}" y="{legend_y}">{SUCCESS_LABELS["success_once"]}</text>')
    parts.append("</svg>")
    return "".join(parts)


def _reward(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def _instructions(b: Rates) -> str:
    """A task's instruction (its first and how many more, all of them on hover); ``–`` for none (the run's
    row) or an empty one (PushT's)."""
    said = (b.instructions if isinstance(b, TaskRates) else None) or []
    if not said or said == [""]:
        return "<td>–</td>"
    more = f" <span class=sub>(+{len(said) - 1} more)</span>" if len(said) > 1 else ""
    return f"<td title='{_e('; '.join(said[:20]))}'>{_e(said[0])}{more}</td>"


def _task_table(summary: RunSummary) -> str:
    rewards = summary.avg_max_reward is not None
    out = ["<table><tr><th>task</th><th>instruction</th><th>episodes</th><th>success (end)</th><th>95% CI</th>"
           "<th>success (any chunk end)</th><th>95% CI</th>"
           + ("<th>avg max reward</th><th>avg sum reward</th>" if rewards else "") + "<th>errors</th></tr>"]
    for name, b in _rows(summary):
        lo, hi = b.ci95 or (None, None)
        lo2, hi2 = b.success_once_ci95 or (None, None)
        reward_cells = (f"<td class=num>{_reward(b.avg_max_reward)}</td><td class=num>{_reward(b.avg_sum_reward)}</td>"
                        if rewards else "")
        out.append(f"<tr><td>{_e(name)}</td>{_instructions(b)}"
                   f"<td class=num>{b.n_episodes}</td>"
                   f"<td class=num>{_pct(b.success_rate)}</td><td>{_pct(lo)} – {_pct(hi)}</td>"
                   f"<td class=num>{_pct(b.success_once_rate)}</td><td>{_pct(lo2)} – {_pct(hi2)}</td>"
                   f"{reward_cells}<td class=num>{b.n_errors}</td></tr>")
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


def task_label(name: str | None) -> str:
    """A readable task name: ``pick_and_place_next_to`` → "Pick and place next to", ``x.PickTask`` → "Pick"."""
    if not name:
        return "unknown"
    name = str(name).rsplit(".", 1)[-1]
    name = re.sub(r"Task$", "", name) or name
    words = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", " ", name).replace("_", " ").split()
    text = " ".join(words).lower()
    return text[:1].upper() + text[1:]


def failure_reason(r: EpisodeResult) -> str | None:
    """The failure class of an episode (errors grouped by their message with numbers and locations masked)."""
    if r.error is not None:
        msg = re.sub(r" \(at [^)]*\)$", "", r.error)
        return "error: " + re.sub(r"\d+(\.\d+)?", "#", msg)
    if r.success:
        return None
    return "succeeded at a chunk end, not at the end" if r.success_once else "never succeeded"


def _group_table(title: str, groups: dict[Any, list[EpisodeResult]], label: Any) -> str:
    """Success per group (house, object category) with Wilson CIs, worst first."""
    rows = []
    for key, rs in groups.items():
        k = sum(r.success for r in rs)
        rows.append((k / len(rs), key, rs, k))
    rows.sort(key=lambda x: (x[0], str(x[1])))
    out = [f"<table class=grp><tr><th>{_e(title)}</th><th>episodes</th><th>success (end)</th><th>95% CI</th>"
           "<th>errors</th></tr>"]
    for rate, key, rs, k in rows:
        lo, hi = wilson_ci(k, len(rs))
        out.append(f"<tr><td>{_e(label(key))}</td><td class=num>{len(rs)}</td><td class=num>{_pct(rate)} "
                   f"<span class=bar style='width:{rate * 60:.0f}px'></span></td><td>{_pct(lo)} – {_pct(hi)}</td>"
                   f"<td class=num>{sum(r.error is not None for r in rs)}</td></tr>")
    out.append("</table>")
    return "".join(out)


def _breakdowns(results: list[EpisodeResult]) -> str:
    """Success per object category and per house, each where the episodes have one (an env suite's have neither)."""
    houses: dict[Any, list[EpisodeResult]] = {}
    cats: dict[Any, list[EpisodeResult]] = {}
    for r in results:
        houses.setdefault(r.house_index, []).append(r)
        cats.setdefault((r.extra or {}).get("object_category"), []).append(r)
    parts = []
    if any(k is not None for k in cats):
        parts.append("<div><h3>Per object category</h3>"
                     + _group_table("object category", cats, lambda k: "unknown" if k is None else k) + "</div>")
    if any(k is not None for k in houses):
        parts.append("<div><h3>Per house</h3>"
                     + _group_table("house", houses, lambda k: "unknown" if k is None else f"house {k}") + "</div>")
    return "".join(["<h2>Breakdowns</h2><div class=cols>", *parts, "</div>"]) if parts else ""


def _failure_groups(results: list[EpisodeResult]) -> tuple[str, dict[int, int]]:
    """The grouped failure table, and episode index → group number."""
    groups: dict[str, list[EpisodeResult]] = {}
    for r in sorted(results, key=lambda r: r.episode_index):
        reason = failure_reason(r)
        if reason is not None:
            groups.setdefault(reason, []).append(r)
    ordered = sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0]))
    number = {r.episode_index: g for g, (_, rs) in enumerate(ordered, 1) for r in rs}
    if not ordered:
        return "<p>No failures.</p>", number
    n_fail = sum(len(rs) for _, rs in ordered)
    out = [f"<p class=sub>{n_fail} of {len(results)} episodes failed.</p><table><tr><th></th><th>reason</th>"
           "<th>episodes</th><th>share</th><th>which</th></tr>"]
    for g, (reason, rs) in enumerate(ordered, 1):
        which = ", ".join(f"<a href='#ep{r.episode_index}'>{r.episode_index}</a>" for r in rs[:25])
        if len(rs) > 25:
            which += f", … {len(rs) - 25} more"
        example = rs[0].error or ""
        out.append(f"<tr id=reason{g}><td class=num>F{g}</td><td title='{_e(example)}'>{_e(reason)}</td>"
                   f"<td class=num>{len(rs)}</td><td class=num>{_pct(len(rs) / len(results))}</td>"
                   f"<td class=which>{which}</td></tr>")
    out.append("</table>")
    return "".join(out), number


def _first_success_svg(results: list[EpisodeResult], policy_dt_s: float) -> str:
    """Histogram of the time to first success (seconds) over the episodes that ever succeeded."""
    times = sorted(r.extra["first_success_step"] * policy_dt_s for r in results
                   if r.success_once and (r.extra or {}).get("first_success_step") is not None)
    if not times:
        return "<p class=sub>No episode succeeded at any step (or the run predates this measurement).</p>"
    hi = max(times[-1], policy_dt_s)
    n_bins = max(1, min(20, len(times)))
    width_s = hi / n_bins
    counts = [0] * n_bins
    for t in times:
        counts[min(n_bins - 1, int(t / width_s))] += 1
    left, w, h, top = 40, 420, 120, 10
    bw = w / n_bins
    peak = max(counts)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + w + 20}" height="{h + top + 34}" '
             'font-family="system-ui,sans-serif" font-size="11" role="img" aria-label="time to first success">']
    for i, c in enumerate(counts):
        bh = h * c / peak
        parts.append(f'<rect x="{left + i * bw + 1:.1f}" y="{top + h - bh:.1f}" width="{bw - 2:.1f}" height="{bh:.1f}" '
                     f'fill="#1a73e8"><title>{i * width_s:.1f}–{(i + 1) * width_s:.1f} s: {c}</title></rect>')
    parts.append(f'<line x1="{left}" y1="{top + h}" x2="{left + w}" y2="{top + h}" stroke="#999"/>')
    for tick in range(5):
        x = left + tick * w / 4
        parts.append(f'<text x="{x:.1f}" y="{top + h + 14}" text-anchor="middle" fill="#666">'
                     f'{hi * tick / 4:.1f}</text>')
    parts.append(f'<text x="{left + w / 2}" y="{top + h + 30}" text-anchor="middle" fill="#444">seconds to first '
                 f'success</text><text x="{left - 6}" y="{top + 8}" text-anchor="end" fill="#666">{peak}</text></svg>')
    median = times[len(times) // 2] if len(times) % 2 else (times[len(times) // 2 - 1] + times[len(times) // 2]) / 2
    p90 = times[min(len(times) - 1, int(0.9 * len(times)))]
    return (f"<p class=sub>{len(times)} of {len(results)} episodes succeeded at some step; median {median:.1f} s, "
            f"90th percentile {p90:.1f} s, fastest {times[0]:.1f} s.</p>" + "".join(parts))


def _episode_rows(results: list[EpisodeResult], videos: dict[int, list[tuple[str, str]]],
                  groups: dict[int, int], policy_dt_s: float, output_dir: Path | None) -> str:
    houses = any(r.house_index is not None for r in results)
    rewards = any("max_reward" in (r.extra or {}) for r in results)
    head = ("<table id=episodes><tr><th>glance (first | last)</th><th>#</th>" + "<th>house</th>" * houses
            + "<th>task</th><th>instruction</th><th>outcome</th><th>any chunk end</th><th>first success</th>"
            + "<th>max reward</th><th>sum reward</th>" * rewards + "<th>steps</th><th>seed</th><th>time</th>"
            "<th>video</th></tr>")
    out = [head]
    for r in sorted(results, key=lambda r: r.episode_index):
        extra = r.extra or {}
        if r.error is not None:
            status = '<span class="fail">error</span>'
        else:
            status = '<span class="ok">success</span>' if r.success else '<span class="fail">failure</span>'
        if r.episode_index in groups:
            g = groups[r.episode_index]
            status += f' <a class=tag href="#reason{g}" title="{_e(r.error or failure_reason(r))}">F{g}</a>'
        clips = "".join(f'<video src="{_e(src)}" title="{_e(cam)}" controls muted preload="metadata"></video>'
                        for cam, src in videos.get(r.episode_index, []))
        thumb = extra.get("thumbnail")
        if thumb and (output_dir is None or (output_dir / thumb).is_file()):
            thumb_html = f'<img src="{_e(thumb)}" alt="episode {r.episode_index}: first and last frame" loading=lazy>'
        else:
            thumb_html = ""
        first = extra.get("first_success_step")
        first_s = f"{first * policy_dt_s:.1f}s" if first is not None else "–"
        outcome = "error" if r.error is not None else ("success" if r.success else "failure")
        house = f"<td class=num>{_e(r.house_index)}</td>" if houses else ""
        reward = (f"<td class=num>{_reward(extra.get('max_reward'))}</td>"
                  f"<td class=num>{_reward(extra.get('sum_reward'))}</td>" if rewards else "")
        out.append(
            f"<tr id=ep{r.episode_index} data-outcome={outcome}><td>{thumb_html}</td>"
            f"<td class=num>{r.episode_index}</td>{house}"
            f"<td title='{_e(r.task_cls)}'>{_e(task_label(r.task_type or r.task_cls))}</td><td>{_e(r.prompt)}</td>"
            f"<td>{status}</td><td>{'yes' if r.success_once else 'no'}</td><td class=num>{first_s}</td>"
            f"{reward}<td class=num>{r.steps}</td><td class=num>{r.seed}</td>"
            f"<td class=num>{r.duration_s:.1f}s</td><td>{clips}</td></tr>")
    out.append("</table>")
    return "".join(out)


_FILTER = """<p class=filter><label><input type=radio name=show value=all checked> all episodes</label>
<label><input type=radio name=show value=failures> failures only</label>
<label><input type=radio name=show value=error> errors only</label></p>
<script>
document.querySelectorAll("input[name=show]").forEach(function (el) {
  el.addEventListener("change", function () {
    var v = el.value;
    document.querySelectorAll("#episodes tr[data-outcome]").forEach(function (tr) {
      var o = tr.dataset.outcome;
      tr.hidden = v === "failures" ? o === "success" : v === "error" ? o !== "error" : false;
    });
  });
});
</script>"""


def render_report(summary: RunSummary, results: list[EpisodeResult],
                  videos: dict[int, list[tuple[str, str]]] | None = None, output_dir: Path | None = None) -> str:
    """The report page as a string; ``output_dir`` (if given) is checked for each thumbnail."""
    bench = summary.benchmark
    policy_name = (summary.policy or {}).get("name", "?")
    lo, hi = summary.ci95 or (None, None)
    title = f"{policy_name} on {bench.name if bench else '?'}"
    versions = ", ".join(f"{k} {v}" for k, v in (summary.versions or {}).items())
    policy_dt_s = float((summary.timing or {}).get("policy_dt_ms", 66.0)) / 1000.0
    failures, groups = _failure_groups(results)
    return "".join([
        "<!doctype html><html lang=en><head><meta charset=utf-8>",
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1><p class=sub>benchmark sha256 <code>{_e(((bench and bench.sha256) or '')[:16])}</code> · "
        f"seed {_e(summary.seed)} · {summary.n_episodes} episodes "
        f"({summary.n_errors} errors) · {_e(summary.started_at or '')}</p>",
        f"<p><span class=big>{_pct(summary.success_rate)}</span> success at the end "
        f"(95% CI {_pct(lo)} – {_pct(hi)}) · {_pct(summary.success_once_rate)} at any chunk end · "
        f"{summary.n_success}/{summary.n_episodes}"
        + ("" if summary.avg_max_reward is None else f" · avg max reward {_reward(summary.avg_max_reward)}, "
           f"avg sum reward {_reward(summary.avg_sum_reward)}") + "</p>",
        f"<p class=sub>{_e(summary.primary_metric)}. Errored episodes count as failures.</p>",
        _parity_notes(summary),
        "<h2>Per task</h2>", _task_table(summary), "<div style='margin-top:1rem'>", _bars_svg(summary), "</div>",
        "<h2>Failures</h2>", failures,
        _breakdowns(results),
        "<h2>Time to first success</h2>", _first_success_svg(results, policy_dt_s),
        "<h2>Episodes</h2>", _FILTER, _episode_rows(results, videos or {}, groups, policy_dt_s, output_dir),
        f"<p class=sub style='margin-top:2rem'>{_e(versions)}</p></body></html>\n",
    ])


def _parity_notes(summary: RunSummary) -> str:
    """The episodes the other ``task_rules`` would have judged otherwise (their scores stand)."""
    notes = summary.parity_notes or []
    if not notes:
        return ""
    items = "".join(f"<li>episode {n.episode_index}: {_e('; '.join(n.notes))}</li>" for n in notes)
    return (f"<p class=sub>{len(notes)} episode{'s' * (len(notes) != 1)} judged otherwise by the other "
            f"<code>task_rules</code> (scored by this run's rules; <code>parity_notes</code>):</p><ul>{items}</ul>")


def write_report(output_dir: Path | str, summary: RunSummary, results: list[EpisodeResult]) -> Path:
    """Write ``output_dir/report.html`` (atomically) and return its path."""
    output_dir = Path(output_dir)
    page = render_report(summary, results, episode_videos(output_dir), output_dir)
    path = output_dir / REPORT_FILE
    return atomic_write(path, page, root=output_dir)
