"""``molmo-eval policy=P benchmark=B workers=N [key=value ...]``: evaluate a policy.

Arguments are Hydra overrides of ``conf/eval.yaml`` (plus config dirs that plugins add).
``--cfg`` prints the resolved config and exits.
"""

from __future__ import annotations

import os
import sys

USAGE = """usage: molmo-eval [--cfg] [key=value ...]

  molmo-eval policy=scripted benchmark=pick_v1 workers=2 [limit=K] [seed=S] [output_dir=D]
             [record=true] [push=true hub.repo_id=ns/name] [executor=local|ray] [resume=true]

Every key of conf/eval.yaml can be overridden; policy/benchmark/executor pick config groups.
"""


def main(argv: list[str] | None = None) -> int:
    from molmo_lerobot.runner.supervisor import reaping_children

    with reaping_children():  # exit only after every child process is reaped
        return _main(argv)


def _main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if any(a in ("-h", "--help") for a in args):
        print(USAGE)
        return 0
    os.environ.setdefault("MUJOCO_GL", "egl")
    from omegaconf import OmegaConf

    from molmo_lerobot.config import ConfigError, compose
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.runner.evaluate import RunError, run_evaluation
    from molmo_lerobot.runner.supervisor import RunInterrupted, WorkerStartError

    expected: tuple[type[BaseException], ...] = (ConfigError, PluginError, RunError, WorkerStartError)
    try:
        from molmo_lerobot.benchmark.load import BenchmarkError

        expected += (BenchmarkError,)
        cfg = compose([a for a in args if a != "--cfg"])
        if "--cfg" in args:
            print(OmegaConf.to_yaml(cfg))
            return 0
        res = run_evaluation(cfg)
    except expected as exc:
        print(f"molmo-eval: error: {exc}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:
        print(f"molmo-eval: {exc}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print("molmo-eval: interrupted; finished episodes are kept in episodes.jsonl "
              "(rerun with resume=true to continue)", file=sys.stderr)
        return 130
    s = res.summary
    lo, hi = s["ci95"]
    print(f"{s['benchmark']['name']} · {s['policy']['name']}: success {s['success_rate']:.3f} "
          f"[{lo:.3f}, {hi:.3f}] ({s['n_success']}/{s['n_episodes']}), success at any step "
          f"{s['success_once_rate']:.3f}, errors {s['n_errors']}")
    for task, block in s["per_task"].items():
        print(f"  {task}: {block['success_rate']:.3f} ({block['n_success']}/{block['n_episodes']})")
    for err in s["errors"][:10]:
        print(f"  episode {err['episode_index']}: {err['error']}")
    print(f"outputs: {res.output_dir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
