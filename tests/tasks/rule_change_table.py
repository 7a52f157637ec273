"""Before/after table of the success-rule changes on the shipped v1 benchmarks (one trajectory per episode).

The scripted expert plays each episode once; after every policy step both the current rule and
the previous one (the task modules of a given git commit, loaded from files) judge the same
simulator state, so the difference is the rule change alone. ``success_once`` is sampled as the
rollout samples it (after each action chunk and at the end); the previous code sampled every step.

    python tests/tasks/rule_change_table.py OLD_RULES_DIR BENCHMARK [LIMIT]

``OLD_RULES_DIR`` holds ``old_pick.py``, ``old_pick_and_place.py`` and ``old_open_close.py``
(``git show <commit>:src/molmo_lerobot/tasks/<name>.py``). Prints one JSON line.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.scripted import ScriptedExpert
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import episode_seed, plan_spec, resolve_horizon
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Timing


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def old_task_types(old_dir: Path) -> dict:
    types = {}
    for name in ("pick", "pick_and_place", "open_close"):
        module = _load(old_dir / f"old_{name}.py")
        for tt in module.molmo_task_types():
            types[tt.name] = tt
    return types


class BothRules:
    """A task for the rollout that is the current rule, and also tracks the previous rule's verdicts."""

    def __init__(self, new, old) -> None:
        self.new, self.old = new, old
        self.old_last = self.old_any = False

    def setup(self) -> None:
        self.new.setup()
        self.old.setup()

    def success(self) -> bool:
        self.old_last = bool(self.old.success())
        self.old_any |= self.old_last
        return self.new.success()

    def reward(self):
        return self.new.reward()


def main(old_dir: str, bench: str, limit: int | None = None) -> dict:
    run = RunContext.build()
    plugins = run.plugins
    olds = old_task_types(Path(old_dir))
    episodes = json.loads((data_path("benchmarks") / bench / "benchmark.json").read_text())[:limit]
    policy = ScriptedExpert({})
    timing = Timing()
    rows = []
    for i, raw in enumerate(episodes):
        spec = parse_episode(raw, plugins)
        tt = plugins.task_type(spec.task_name)
        env = build_env(spec, timing, run)
        seed = episode_seed(0, raw)  # molmo-eval's seed for this episode with seed=0
        env.reset(seed)
        new = tt.create(spec, env)
        old = olds[tt.name].create(spec, env)
        task = BothRules(new, old)
        horizon = resolve_horizon(None, spec.task, tt.default_horizon_sec, timing.policy_dt_ms)
        try:
            plan = plan_spec(spec, run.plugins, seed=seed, horizon=horizon)
            out = rollout(EpisodeSession.start(plan, spec, env, task, run, policy=policy), policy, [], "scripted")
            rows.append({"i": i, "new": out.success, "new_once": out.success_once,
                         "new_any_step": out.extra["success_any_step"], "old": task.old_last, "old_once": task.old_any})
        except Exception as exc:  # an expert failure counts as a failure under both rules
            rows.append({"i": i, "new": False, "new_once": False, "new_any_step": False, "old": False,
                         "old_once": False, "error": f"{type(exc).__name__}: {exc}"})
        finally:
            env.close()
    n = len(rows)
    summary = {"benchmark": bench, "n": n, **{k: sum(r[k] for r in rows) for k in
                                                ("old", "new", "old_once", "new_once", "new_any_step")},
               "flipped": [r["i"] for r in rows if r["old"] != r["new"]],
               "errors": sum("error" in r for r in rows)}
    return summary


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else None)), flush=True)
