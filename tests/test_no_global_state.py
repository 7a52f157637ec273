"""No module of ``molmo_lerobot`` holds mutable run state: a run's plugins, settings and asset
catalog live in its :class:`~molmo_lerobot.context.RunContext`, handed down explicitly.

Every module is imported, then its source is checked for the holders of such state:
``global`` statements, ``globals()`` edits, zero-argument functions under ``functools.cache`` /
``lru_cache`` (a process-wide singleton), ``.cache_clear()`` calls (resetting one), and
module-level dicts, lists and sets that the module mutates. Immutable tables (tuples,
frozensets, mappings never written to) pass. :data:`PROCESS_CACHES` are the few caches of
process resources that are not run state; each says why it is allowed.
"""

from __future__ import annotations

import ast
import importlib
import pkgutil
from pathlib import Path

import molmo_lerobot

#: ``(module, name) → why`` for process-wide caches that hold no run state
PROCESS_CACHES = {
    ("molmo_lerobot.sim.env", "_MODEL_CACHE"):
        "compiled MuJoCo models keyed by everything that defines them (a compile cache, the same for every run)",
    ("molmo_lerobot.sim.render", "_PROCESS_RENDERERS"):
        "the process's one OpenGL context and its render contexts per compiled model (a GPU resource, no run state)",
    ("molmo_lerobot.resources.index", "_ENVS"): "LMDB allows one open handle per environment and process",
    ("molmo_lerobot.resources.index", "_ENVS_PID"): "the process the LMDB handles belong to (reset after fork)",
    ("molmo_lerobot.robots.franka", "_base_xml"): "constant MJCF text read from the installed package",
    ("molmo_lerobot.content.libero.objects", "_file_owners"):
        "which installed LIBERO distribution lists each asset file (their dist-info RECORDs, the same for every run)",
}

MUTATORS = {"append", "extend", "insert", "update", "setdefault", "pop", "popitem", "clear", "add", "discard",
            "remove", "move_to_end", "appendleft", "extendleft"}
CONTAINERS = {"dict", "list", "set", "OrderedDict", "defaultdict", "deque", "Counter"}


def _modules() -> list[str]:
    root = Path(molmo_lerobot.__file__).parent
    return ["molmo_lerobot", *sorted(m.name for m in pkgutil.walk_packages([str(root)], "molmo_lerobot."))]


def _is_cache(decorator: ast.expr) -> bool:
    target = decorator.func if isinstance(decorator, ast.Call) else decorator
    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
    return name in ("cache", "lru_cache")


def _mutable_literal(value: ast.expr | None) -> bool:
    if isinstance(value, (ast.Dict, ast.List, ast.Set, ast.DictComp, ast.ListComp, ast.SetComp)):
        return True
    if isinstance(value, ast.Call):
        func = value.func
        return (func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")) in CONTAINERS
    return False


def holders(source: str) -> dict[str, str]:
    """``name → what makes it a holder`` for one module's source."""
    tree = ast.parse(source)
    found: dict[str, str] = {}
    containers = set()
    for node in tree.body:
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AnnAssign) else [])
        if _mutable_literal(getattr(node, "value", None)):
            containers |= {t.id for t in targets if isinstance(t, ast.Name)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Global):
            for name in node.names:
                found[name] = f"global statement (line {node.lineno})"
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args
            if (any(_is_cache(d) for d in node.decorator_list)
                    and not (args.posonlyargs or args.args or args.vararg or args.kwonlyargs or args.kwarg)):
                found[node.name] = f"zero-argument function under functools.cache (line {node.lineno})"
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            owner = node.func.value
            if node.func.attr == "cache_clear":
                found[ast.unparse(owner)] = f".cache_clear() call (line {node.lineno})"
            elif isinstance(owner, ast.Call) and getattr(owner.func, "id", "") == "globals":
                found["globals()"] = f"globals().{node.func.attr}() (line {node.lineno})"
            elif isinstance(owner, ast.Name) and owner.id in containers and node.func.attr in MUTATORS:
                found[owner.id] = f"module-level container mutated by .{node.func.attr}() (line {node.lineno})"
        elif isinstance(node, (ast.Assign, ast.AugAssign, ast.Delete)):
            for t in node.targets if isinstance(node, (ast.Assign, ast.Delete)) else [node.target]:
                if isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name) and t.value.id in containers:
                    found[t.value.id] = f"module-level container written by item (line {node.lineno})"
    return found


def test_no_module_holds_mutable_run_state():
    problems, seen = [], set()
    for name in _modules():
        module = importlib.import_module(name)
        for holder, why in holders(Path(module.__file__).read_text()).items():
            seen.add((name, holder))
            if (name, holder) not in PROCESS_CACHES:
                problems.append(f"{name}: {holder}: {why}")
    assert not problems, "mutable run state outside RunContext:\n" + "\n".join(problems)
    assert set(PROCESS_CACHES) <= seen, f"PROCESS_CACHES names what is gone: {sorted(set(PROCESS_CACHES) - seen)}"


def test_the_checker_sees_each_kind_of_holder():
    source = """
from functools import cache
_CURRENT = None
_REGISTRY = {}
TABLE = {"a": 1}
def configure(x):
    global _CURRENT
    _CURRENT = x
@cache
def get_registry():
    return Registry()
@cache
def memo(key):
    return key
def register(name, item):
    _REGISTRY[name] = item
def reset():
    get_registry.cache_clear()
def read():
    return TABLE["a"]
"""
    assert set(holders(source)) == {"_CURRENT", "get_registry", "_REGISTRY"}
