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
    args = list(sys.argv[1:] if argv is None else argv)
    if any(a in ("-h", "--help") for a in args):
        print(USAGE)
        return 0
    os.environ.setdefault("MUJOCO_GL", "egl")
    from omegaconf import OmegaConf

    from molmo_lerobot.config import ConfigError, compose
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.runner.evaluate import RunError, run_evaluation
    from molmo_lerobot.runner.local import WorkerStartError
    from molmo_lerobot.runner.run_config import RunConfigError

    expected: tuple[type[BaseException], ...] = (ConfigError, PluginError, RunError, WorkerStartError,
                                                 RunConfigError)
    try:
        from molmo_lerobot.benchmark.load import BenchmarkError

        expected += (BenchmarkError,)
        cfg = compose([a for a in args if a != "--cfg"])
        if "--cfg" in args:
            print(OmegaConf.to_yaml(cfg))
            return 0
        res = run_evaluation(cfg)
    except expected as exc:
        for line in str(exc).splitlines() or [type(exc).__name__]:
            print(f"molmo-eval: error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("molmo-eval: interrupted; finished episodes are kept in episodes.jsonl "
              "(rerun with resume=true to continue)", file=sys.stderr)
        return 130
    from molmo_lerobot.runner.results import summary_lines

    print("\n".join([*summary_lines(res.summary), f"outputs: {res.output_dir}"]))
    return 0 if res.summary["success_rate"] is not None else 1  # 1: no episode ran, so there is no score


if __name__ == "__main__":
    raise SystemExit(main())
