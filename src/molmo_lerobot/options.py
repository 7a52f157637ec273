"""A config group validated against its pydantic model: one line per problem, each naming its dotted key.

The run config (:class:`~molmo_lerobot.run_config.RunConfig`) and the groups a plugin's model
describes (``policy``: :class:`~molmo_lerobot.policies.base.PolicyOptions`) report alike:
``policy.chunk: expected an integer in 1..10000, got 0``, or one line naming a section's
unknown keys (``policy.sclae: unknown key (known: name, …)``). A validator raises :func:`problem`
with ``{key}`` where the dotted key goes; :func:`rule` makes one from a predicate.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from pydantic import BaseModel, BeforeValidator, ValidationError
from pydantic_core import PydanticCustomError

from molmo_lerobot.errors import MolmoError

#: the pydantic error type of :func:`problem`
PROBLEM = "run_config"


class OptionsError(MolmoError, ValueError):
    """A config group is invalid; ``problems`` holds one line per problem."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


def is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def optional(ok: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda v: v is None or ok(v)


def problem(text: str) -> PydanticCustomError:
    """A problem line; ``{key}`` in it becomes the dotted key (see :func:`problem_lines`)."""
    return PydanticCustomError(PROBLEM, text)  # no context: pydantic leaves the text as it is


def rule(ok: Callable[[Any], bool], text: str) -> BeforeValidator:
    """Values for which ``ok`` is false fail with ``text`` (``{key}``: the key, ``{got}``: the value)."""
    def check(value: Any) -> Any:
        if not ok(value):
            raise problem(text.replace("{got}", repr(value)))
        return value
    return BeforeValidator(check)


def bounded(low: float, high: float, *, integer: bool) -> BeforeValidator:
    """A number (``integer``: a whole one) in ``low..high``."""
    kind = "an integer" if integer else "a number"
    return rule(lambda v: (is_int(v) if integer else is_number(v)) and math.isfinite(v) and low <= v <= high,
                f"{{key}}: expected {kind} in {low:g}..{high:g}, got {{got}}")


def section_model(model: type[BaseModel], path: str) -> type[BaseModel] | None:
    """The model of the section at the dotted ``path`` of ``model`` (``""``: ``model`` itself); ``None``
    for a path into a field that is no model (a free-form map)."""
    for part in [p for p in path.split(".") if p]:
        field = model.model_fields.get(part)
        if field is None or not (isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel)):
            return None
        model = field.annotation
    return model


def problem_lines(exc: ValidationError, model: type[BaseModel], prefix: str = "") -> list[str]:
    """One line per problem of validating ``model``, each naming its key (``prefix`` + the error's
    location); a section's unknown keys in one line, with the keys the section knows."""
    out: list[str] = []
    unknown: dict[str, list[str]] = {}
    for error in exc.errors():
        where = ".".join(str(p) for p in error["loc"])
        key = ".".join(filter(None, [prefix, where]))
        if error["type"] == PROBLEM:
            out.extend(error["msg"].replace("{key}", key).splitlines())
        elif error["type"] == "missing":
            out.append(f"{key}: missing (it has no default)")
        elif error["type"] == "extra_forbidden":
            section, _, name = where.rpartition(".")
            unknown.setdefault(section, []).append(name)
        else:
            msg = error["msg"]
            out.append(f"{key}: {msg[:1].lower()}{msg[1:]}, got {error['input']!r}")
    for section, names in unknown.items():
        keys = ", ".join(".".join(filter(None, [prefix, section, name])) for name in sorted(names))
        known = section_model(model, section)
        out.append(f"{keys}: unknown key{'s' if len(names) > 1 else ''} "
                   f"(known: {', '.join(known.model_fields if known else [])})")
    return out


def validate_group[M: BaseModel](group: str, model: type[M], data: Mapping[str, Any]) -> M:
    """The config group ``group`` (``policy``) validated by ``model``; :class:`OptionsError` lists every
    problem, each naming ``<group>.<key>``."""
    try:
        return model.model_validate(dict(data))
    except ValidationError as exc:
        raise OptionsError(problem_lines(exc, model, group)) from None
