"""The dataset card (``README.md``): LeRobot's card saying in prose what the data is (simulated:
MuJoCo, robot, cameras, tasks), how it is scored (the score table) and its limitations."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from molmo_lerobot.features import IMAGE_PREFIX, STATE
from molmo_lerobot.results import Rates, RunSummary

if TYPE_CHECKING:
    from molmo_lerobot.dataset_layout import DatasetLayout

TAGS = ["molmo-lerobot", "evaluation", "rollouts", "mujoco", "simulation", "synthetic"]


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * float(x):.1f}%"


def _ci(ci: tuple[float, float] | None) -> str:
    if ci is None:  # no episode simulated: no interval
        return "n/a"
    lo, hi = ci
    return f"[{_pct(lo)}, {_pct(hi)}]"


def score_table(summary: RunSummary) -> str:
    """Markdown table: overall and per-task success (at the end and at any chunk end) with Wilson 95% CIs."""
    rows: list[tuple[str, Rates]] = [("**all**", summary), *((f"`{t}`", b) for t, b in summary.per_task.items())]
    lines = [
        "| task | episodes | success (end) | 95% CI | success (any chunk end) | 95% CI | errors |",
        "|---|---:|---:|---|---:|---|---:|",
    ]
    for name, b in rows:
        lines.append(
            f"| {name} | {b.n_episodes} | {_pct(b.success_rate)} | {_ci(b.ci95)} "
            f"| {_pct(b.success_once_rate)} | {_ci(b.success_once_ci95)} | {b.n_errors} |"
        )
    return "\n".join(lines)


def _cameras(meta_info: dict[str, Any]) -> list[str]:
    """``exterior`` (224x224) for each video feature of LeRobot's ``meta/info.json``."""
    out = []
    for key, feature in (meta_info.get("features") or {}).items():
        if feature.get("dtype") == "video":
            h, w = list(feature.get("shape") or [0, 0])[:2]
            out.append(f"`{key.removeprefix(IMAGE_PREFIX)}` ({w}x{h})")
    return out


def _what_it_holds(meta_info: dict[str, Any], layout: DatasetLayout | None) -> str:
    """What the frames are and what ``observation.state`` and ``action`` hold: our robots' joint positions and
    targets, or an env suite's layout's own account of each of its features (their dtypes and shapes as stored)."""
    features = meta_info.get("features") or {}
    robot = f"Robot: `{meta_info.get('robot_type') or 'unknown'}`"
    if layout is None:
        state = (features.get(STATE) or {}).get("shape") or ["?"]
        return ("the scenes, the robot and its cameras are simulated in the MuJoCo physics engine, and the images "
                f"are MuJoCo renders; nothing was recorded on a real robot. {robot}, with its {state[0]} joint "
                "positions as `observation.state` and the commanded joint targets as `action` (names in "
                "`meta/info.json`). ")
    held = []
    for key, about in layout.describe().items():
        feature = features.get(key) or {}
        shape = "x".join(str(n) for n in feature.get("shape") or [])
        held.append(f"`{key}` ({feature.get('dtype', '?')} {shape}): {about}")
    return (f"{layout.simulator}; nothing was recorded on a real robot. {robot}. Each frame holds "
            + "; ".join(held) + ". ")


def description(meta_info: dict[str, Any], summary: RunSummary, records: list[dict[str, Any]],
                layout: DatasetLayout | None = None) -> str:
    """The card's prose: what the data is (simulated), robot, sensors, tasks, scores, limitations; ``layout``: an
    env suite's recording, whose features it describes."""
    bench_name = summary.benchmark.name if summary.benchmark else "?"
    policy_name = (summary.policy or {}).get("name", "?")
    sha = (summary.benchmark and summary.benchmark.sha256) or ""
    stored = [r for r in records if r.get("episode_index") is not None]
    held = [r for r in stored if r.get("frames", r["steps"]) < r["steps"]]
    prompts = sorted({str(r.get("prompt")) for r in stored if r.get("prompt")})
    tasks = sorted(summary.per_task.items())
    cameras = _cameras(meta_info)
    fps = meta_info.get("fps")
    lines = [
        f"Evaluation rollouts of policy `{policy_name}` on benchmark `{bench_name}` "
        f"(sha256 `{sha[:16]}`), recorded with molmo_lerobot.",
        "",
        "**Simulated data.** Every frame is synthetic: " + _what_it_holds(meta_info, layout) +
        f"Sensors: {len(cameras)} simulated RGB camera(s), {', '.join(cameras) or 'none'}, at {fps} fps; "
        "no depth, force or tactile sensing. "
        f"Task(s): {', '.join(f'`{t}` ({b.n_episodes} episodes)' for t, b in tasks) or 'none'}; "
        + (f"each episode's language instruction is its LeRobot task ({len(prompts)} distinct, "
           f"e.g. \"{prompts[0]}\")." if prompts else
           "the episodes have no language instruction; their LeRobot task is the task's name."),
        "",
        f"**Scores.** The benchmark's success rule judges each episode on the simulator state; the primary "
        f"metric is {summary.primary_metric}. Every attempted episode counts; errored "
        "episodes count as failures and are not stored as dataset episodes.",
        "",
        score_table(summary),
        "",
        f"{len(stored)} of {summary.n_episodes} attempted episodes are stored. "
        "`meta/eval/episodes.jsonl` maps every attempted episode (dataset `episode_index`, or null when "
        "not stored) to its outcome, seed, house, policy and benchmark hash; `results.json` is the run summary.",
    ]
    if held:
        lines += ["", f"{len(held)} stored episode(s) are demonstrations of a scripted expert that end a few "
                  "steps after their first success (`record_hold_steps`): the rollout, and its score, went on "
                  "to the horizon unrecorded, so their `frames` in `meta/eval/episodes.jsonl` are fewer than "
                  "their `steps`."]
    lines += [
        "",
        "**Limitations.** Simulated contact, friction and rendering differ from the real world (no sensor "
        "noise, motion blur or calibration error): a policy trained only on this data should not be expected "
        "to work on a real robot. The scenes, objects and camera poses cover this benchmark's episodes only. "
        "Success is a rule on simulator state, not a human judgement. A scripted expert plans with privileged "
        "simulator state (object poses) that a learned policy does not observe. With few episodes the "
        "confidence intervals above are wide.",
    ]
    return "\n".join(lines)


def make_card(meta_info: Any, summary: RunSummary, repo_id: str, records: list[dict[str, Any]],
              on_hub: bool = False, layout: DatasetLayout | None = None) -> Any:
    """A :class:`huggingface_hub.DatasetCard` from LeRobot's template (``meta_info``: LeRobot's
    ``DatasetInfo``), with this description. ``on_hub`` (``push=true``): the template's "visualize this
    dataset" link to the Hub's viewer; a local dataset instead gets the ``lerobot-dataset-viz`` command
    (the Hub viewer cannot open a dataset that is not on the Hub)."""
    from lerobot.datasets.utils import create_lerobot_dataset_card

    bench = summary.benchmark.name if summary.benchmark else None
    tags = TAGS + ([str(bench)] if bench else [])
    text = description(meta_info.to_dict(), summary, records, layout)
    if not on_hub:
        text += ("\n\n**Visualize** (a local dataset, not on the Hub), from this directory: "
                 f"`lerobot-dataset-viz --repo-id {repo_id} --root . --episode-index 0`")
    return create_lerobot_dataset_card(tags=tags, license="apache-2.0", dataset_info=meta_info,
                                       repo_id=repo_id if on_hub else None, dataset_description=text)
