"""Import circles between the modules of ``src/``, ``TYPE_CHECKING`` imports and imports inside
functions included (import-linter's contracts leave the former out).

A circle is a group of modules each of which reaches every other by imports (a strongly connected
component of grimp's import graph). :data:`KNOWN` lists those not yet broken; a new circle fails,
and so does a known one that is gone (delete it from the list, so it cannot come back).
"""

from __future__ import annotations

import grimp

#: circles not yet broken, each as its set of modules (``molmo_lerobot.`` left out)
KNOWN: list[frozenset[str]] = []


def import_circles(graph: grimp.ImportGraph, package: str = "molmo_lerobot") -> list[frozenset[str]]:
    """Every group of two or more modules of ``graph`` that import each other, round (names
    without ``package.``)."""
    # Tarjan's strongly connected components, iteratively
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[frozenset[str]] = []
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.find_modules_directly_imported_by(child)))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                members = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    members.append(member)
                    if member == node:
                        break
                if len(members) > 1:
                    circles.append(frozenset(m.removeprefix(f"{package}.") for m in members))
    return circles


def test_no_new_import_circles():
    found = import_circles(grimp.build_graph("molmo_lerobot", exclude_type_checking_imports=False, cache_dir=None))
    new = [sorted(c) for c in found if c not in KNOWN]
    gone = [sorted(c) for c in KNOWN if c not in found]
    assert not new, f"new import circles (TYPE_CHECKING imports included): {new}"
    assert not gone, f"these circles are broken: delete them from KNOWN in {__file__}: {gone}"


def test_circles_are_the_groups_that_import_each_other():
    graph = grimp.ImportGraph()
    for module in ("p", "p.a", "p.b", "p.c", "p.d", "p.e"):
        graph.add_module(module)
    for importer, imported in (("p.a", "p.b"), ("p.b", "p.c"), ("p.c", "p.a"), ("p.c", "p.d"), ("p.d", "p.e")):
        graph.add_import(importer=importer, imported=imported)
    assert import_circles(graph, "p") == [frozenset({"a", "b", "c"})]
    graph.add_import(importer="p.e", imported="p.d")
    assert sorted(map(sorted, import_circles(graph, "p"))) == [["a", "b", "c"], ["d", "e"]]


def package_graph(graph: grimp.ImportGraph, package: str = "molmo_lerobot") -> grimp.ImportGraph:
    """``graph`` with every module folded into its top-level package or module under ``package``
    (``molmo_lerobot.runner.worker`` -> ``molmo_lerobot.runner``)."""
    def top(module: str) -> str:
        return ".".join(module.split(".")[:2])

    folded = grimp.ImportGraph()
    for module in graph.modules:
        if module != package:
            folded.add_module(top(module))
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            if module != package and imported != package and top(module) != top(imported):
                folded.add_import(importer=top(module), imported=top(imported))
    return folded


#: package-level circles not yet broken: the plugin registry (``plugins``, ``hookspecs``) names the contract
#: classes it indexes (task types, robots, scenes, policies …) for the type checker, and their packages take a
#: plugin set (``runner``/``export``/``suites`` was one more, broken by the benchmark kinds)
KNOWN_PACKAGE: list[frozenset[str]] = [frozenset({
    "benchmark", "context", "dataset_layout", "hookspecs", "molmospaces", "plugins", "policies", "recording",
    "robots", "run_config", "sim", "tasks"})]


def test_no_new_import_circles_between_packages():
    """The packages and top-level modules of ``molmo_lerobot`` (``runner``, ``suites``, ``plugins`` …) import
    one another one way, ``TYPE_CHECKING`` imports and imports inside functions included, but for
    :data:`KNOWN_PACKAGE`."""
    graph = grimp.build_graph("molmo_lerobot", exclude_type_checking_imports=False, cache_dir=None)
    found = import_circles(package_graph(graph))
    assert [sorted(c) for c in found if c not in KNOWN_PACKAGE] == []
    assert [sorted(c) for c in KNOWN_PACKAGE if c not in found] == [], "broken: delete it from KNOWN_PACKAGE"
