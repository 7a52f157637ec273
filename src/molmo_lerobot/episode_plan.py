"""One episode as a run plays it: :class:`EpisodePlan`, plain data planned in the main process and handed to
the workers (every benchmark kind plans its episodes into these), and the seed an episode's content gives it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from molmo_lerobot.errors import EPISODE
from molmo_lerobot.hashing import content_sha256
from molmo_lerobot.results import EpisodeIdentity, EpisodeResult

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.plugins import Plugins


def episode_seed(run_seed: int, spec: dict[str, Any]) -> int:
    """Seed from the run seed and the episode's identity (its canonical content)."""
    digest = content_sha256(spec, prefix=f"{int(run_seed)}\n", ensure_ascii=True)
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


@dataclass(frozen=True)
class EpisodePlan:
    """One episode as a run plays it: its :class:`~molmo_lerobot.results.EpisodeIdentity` and the spec
    it runs. Plain data: it travels to workers as it is."""

    identity: EpisodeIdentity
    #: the episode as it runs (overrides applied) as JSON; what its seed and digest derive from
    spec: dict[str, Any]
    #: problems of the benchmark's episode (``field: message``), as ``molmo-bench validate`` finds them
    problems: tuple[str, ...] = ()
    #: why it cannot run (an override failed, or it is invalid); it is then recorded, never simulated
    error: str | None = None
    #: the benchmark kind that planned it and plays it (:mod:`molmo_lerobot.benchmark_kinds`)
    kind: str = "episodes"

    @classmethod
    def of(cls, index: int, spec: dict[str, Any], seed: int, task_type: str, prompt: str, horizon: int | None,
           horizon_source: str | None, digest: str, problems: tuple[str, ...] = (),
           error: str | None = None, kind: str = "episodes") -> EpisodePlan:
        """The plan of ``spec``, its identity's house and task class read from it."""
        task = spec.get("task")
        return cls(EpisodeIdentity(index, seed, task_type, prompt, horizon, horizon_source, digest,
                                   spec.get("house_index"), task.get("task_cls") if isinstance(task, dict) else None),
                   spec, problems, error, kind)

    @property
    def episode_index(self) -> int:
        return self.identity.episode_index

    @property
    def seed(self) -> int:
        return self.identity.seed

    @property
    def task_type(self) -> str:
        return self.identity.task_type

    @property
    def prompt(self) -> str:
        return self.identity.prompt

    @property
    def horizon(self) -> int | None:
        return self.identity.horizon

    @property
    def horizon_source(self) -> str | None:
        return self.identity.horizon_source

    @property
    def digest(self) -> str:
        return self.identity.digest

    @property
    def house_index(self) -> int | None:
        return self.identity.house_index

    @property
    def task_cls(self) -> str | None:
        return self.identity.task_cls

    @property
    def steps(self) -> int:
        """:attr:`horizon` of an episode that can run (one whose task type a plugin provides)."""
        if self.horizon is None:
            raise ValueError(f"episode {self.episode_index}: no plugin provides task type {self.task_type!r}")
        return self.horizon

    def episode(self, plugins: Plugins) -> EpisodeSpec:
        """:attr:`spec` validated, its task by the model of the plugin that owns it (what a worker or
        the Gymnasium env builds the episode from)."""
        from molmo_lerobot.benchmark.task_specs import parse_episode

        return parse_episode(self.spec, plugins)

    def described(self) -> dict[str, Any]:
        """What a result records of every attempted episode: task type, prompt, horizon and its source."""
        return {"task_type": self.task_type, "prompt": self.prompt, "horizon": self.horizon,
                "horizon_source": self.horizon_source}

    def failed(self, error: str, kind: str = EPISODE, **kw: Any) -> EpisodeResult:
        """This episode as an error record."""
        return EpisodeResult.failed(self.episode_index, self.house_index, self.task_cls, self.seed, error, kind,
                                    **self.described(), **kw)
