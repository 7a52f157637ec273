"""``molmo-plugins``: list every plugin entry point and what became of it.

Columns: name, kind(s), distribution, version, status (``ok`` or ``error: <reason>``).
``--hooks`` adds, per plugin, the hooks it implements and the names it provides. Every
provider hook is called first, so a plugin whose hook raises shows up as broken. A broken
plugin is listed, never fatal: the command exits 0. Names that several plugins provide are
listed as clashes with their providers (a run using one fails unless its config pins a
provider with ``plugins.prefer.<kind>.<name>=<plugin>``).
"""

from __future__ import annotations

import argparse
import sys

from molmo_lerobot.plugins import KIND_HOOKS, PluginRecord, Plugins


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="molmo-plugins", description="List installed molmo_lerobot plugins.")
    parser.add_argument("--hooks", action="store_true", help="also list the hooks each plugin implements")
    args = parser.parse_args(argv)
    plugins = Plugins()
    clashes = plugins.clashes()  # runs every provider hook, so failing hooks are recorded
    plugins.config_dirs()
    print(format_table(plugins.records))
    if clashes:
        print("\nCLASHES (a run using one of these names fails unless it pins a provider: "
              "plugins.prefer.<kind>.<name>=<plugin>)")
        for line in clash_lines(plugins, clashes):
            print("  " + line)
    if args.hooks:
        for rec in plugins.records:
            print(f"\n{rec.name} ({rec.value})")
            hooks = implemented_hooks(plugins, rec)
            print("  hooks:    " + (", ".join(hooks) or "-"))
            clashing = {f"{kind}:{name}" for kind, name in clashes}
            print("  provides: " + (", ".join(p + (" (clash)" if p in clashing else "") for p in rec.provides) or "-"))
    broken = plugins.broken()
    if broken:
        print(f"\n{len(broken)} of {len(plugins.records)} plugins failed to load; "
              "runs that do not need them are unaffected.", file=sys.stderr)
    return 0


def clash_lines(plugins: Plugins, clashes: dict) -> list[str]:
    """One line per clashing name and its providers; a name's clashing aliases are folded into it."""
    groups: dict[tuple, list[str]] = {}
    for (kind, name), recs in clashes.items():
        groups.setdefault((kind, tuple(r.pm_name for r in recs)), []).append(name)
    lines = []
    for (kind, _), keys in groups.items():
        recs = clashes[(kind, keys[0])]
        primary = [k for k in keys if k in plugins.names(kind)] or keys[:1]
        names = ", ".join(repr(k) for k in primary)
        aliases = [k for k in keys if k not in primary]
        also = f" (and aliases {', '.join(aliases)})" if aliases else ""
        lines.append(f"{kind} {names}{also}: " + ", ".join(r.label for r in recs))
    return lines


def implemented_hooks(plugins: Plugins, rec: PluginRecord) -> list[str]:
    if rec.module is None:
        return []
    return sorted(h.name for h in plugins.pm.get_hookcallers(rec.module) or [] if h.name in KIND_HOOKS)


def format_table(records: list[PluginRecord]) -> str:
    header = ("NAME", "KIND", "DISTRIBUTION", "VERSION", "STATUS")
    rows = [
        (r.name, ",".join(r.kinds) or "-", r.distribution, r.version, "ok" if r.status == "ok" else f"error: {r.error}")
        for r in records
    ]
    if not rows:
        return "no plugins installed (entry-point group molmo_lerobot is empty)"
    widths = [max(len(row[i]) for row in [header, *rows]) for i in range(len(header) - 1)]
    lines = []
    for row in [header, *rows]:
        lines.append("  ".join(cell.ljust(w) for cell, w in zip(row[:-1], widths, strict=True)) + "  " + row[-1])
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
