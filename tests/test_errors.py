"""One exception base: every exception class of molmo_lerobot and of the plugins shipped in
``plugins/`` derives from :class:`~molmo_lerobot.errors.MolmoError`.

Every module is imported and each exception class it defines is checked. :data:`SIGNALS` are the
few that are no error at all: they derive from ``BaseException`` but not ``Exception`` so that no
``except Exception`` stops them, which a ``MolmoError`` base would undo.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import sys
from pathlib import Path

import molmo_lerobot
from molmo_lerobot.errors import ExportError, MolmoError, RunError

ROOT = Path(__file__).resolve().parents[1]

#: ``qualified name → why`` for the control-flow signals that must pass ``except Exception``
SIGNALS = {
    "molmo_lerobot.runner.worker.WorkerStop": "the supervisor stops a worker mid-episode; no episode error",
    "molmo_lerobot.runner.supervisor.RunInterrupted": "SIGINT/SIGTERM; a KeyboardInterrupt like Ctrl-C",
}


def _modules() -> list[str]:
    names = ["molmo_lerobot",
             *(m.name for m in pkgutil.walk_packages([str(Path(molmo_lerobot.__file__).parent)], "molmo_lerobot."))]
    for src in sorted(ROOT.glob("plugins/*/src")):
        if str(src) not in sys.path:
            sys.path.append(str(src))
        for top in pkgutil.iter_modules([str(src)]):
            names.append(top.name)
            if top.ispkg:
                names += [m.name for m in pkgutil.walk_packages([str(src / top.name)], f"{top.name}.")]
    return sorted(names)


def exception_classes() -> dict[str, type[BaseException]]:
    """``module.qualname → class`` for every exception class defined in the package and the plugins."""
    found = {}
    for name in _modules():
        module = importlib.import_module(name)
        for obj in vars(module).values():
            if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == name:
                found[f"{name}.{obj.__qualname__}"] = obj
    return found


def test_every_exception_class_derives_from_molmo_error():
    classes = exception_classes()
    assert len(classes) > 30, sorted(classes)  # the walk reached the package
    outside = sorted(name for name, cls in classes.items() if not issubclass(cls, MolmoError) and name not in SIGNALS)
    assert not outside, f"exception classes not derived from molmo_lerobot.errors.MolmoError: {outside}"
    for name in SIGNALS:
        assert name in classes and not issubclass(classes[name], Exception), name


def test_no_error_name_is_defined_twice():
    """Two ``ExportError``s became one."""
    names = [qualified.rsplit(".", 1)[1] for qualified in exception_classes()]
    assert "ExportError" in names
    assert sorted({n for n in names if names.count(n) > 1}) == []


def test_builtin_bases_stay():
    """Callers that catch the builtin base keep catching it."""
    from molmo_lerobot.fileio import UnsafePathError
    from molmo_lerobot.hookspecs import ConfigError
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.protocol.client import PolicyTimeoutError

    assert issubclass(ConfigError, ValueError) and issubclass(PluginError, LookupError)
    assert issubclass(UnsafePathError, OSError) and issubclass(PolicyTimeoutError, TimeoutError)
    assert issubclass(ExportError, RunError) and issubclass(RunError, RuntimeError)
