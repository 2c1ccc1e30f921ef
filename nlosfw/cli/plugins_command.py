"""``python -m nlosfw plugins [NAME | --check]``: the installed plugins, or one in detail.

The listing checks that each plugin's factory and config modules can be found without
importing them (:meth:`~nlosfw.plugins.PluginSpec.find_problem`), so it stays fast and
imports no heavy backend; ``--check`` and ``plugins NAME`` import them fully. A plugin
whose code cannot be found or imported is shown as broken, with the reason. The listing
is plain text (rich is imported for ``plugins NAME`` only).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any, NoReturn

from nlosfw.common.config_docs import OptionDoc, option_docs
from nlosfw.common.errors import ConfigError
from nlosfw.plugins import CAPABILITIES, LazyFactory, PluginHost, PluginSpec
from nlosfw.plugins.kinds import RUN_KINDS

if TYPE_CHECKING:
    from rich.console import Console, RenderableType
    from rich.table import Table

#: Exit status of ``plugins --check`` and ``plugins NAME`` when a plugin is broken.
BROKEN_EXIT_STATUS = 1

USAGE = """\
python -m nlosfw plugins            every installed plugin, its distribution and status
python -m nlosfw plugins --check    the same, importing every plugin (exit 1 if one is broken)
python -m nlosfw plugins NAME       one plugin: options, capabilities, conformance checks
                                    (each kind that uses the name; KIND:NAME for one of
                                    them, e.g. imager:lct)"""


@dataclass(frozen=True)
class Status:
    """Whether a plugin can be used: ``ok``, ``missing`` (a pip command) or ``broken``."""

    state: str
    detail: str = ""

    def text(self) -> str:
        """The status in words: ``ok``, ``missing: <pip command>``, ``broken: <why>``."""
        return f"{self.state}: {self.detail}" if self.detail else self.state

    def markup(self) -> str:
        """The status as rich markup."""
        from rich.markup import escape

        if self.state == "ok":
            return "[green]ok[/]"
        colour = "yellow" if self.state == "missing" else "red"
        return f"[{colour}]{self.state}: {escape(self.detail)}[/]"


def plugin_status(spec: PluginSpec, full: bool = False) -> Status:
    """The plugin's status: missing requirements first, then its code found (``full``:
    imported)."""
    command = spec.install_command()
    if command:
        return Status("missing", command)
    problem = spec.import_problem() if full else spec.find_problem()
    return Status("broken", problem) if problem else Status("ok")


def plugins_table(host: PluginHost, full: bool = False) -> str:
    """Kind, name, distribution, status (ok, missing: the pip command, broken: why) and
    description: a plain-text table, one line a plugin."""
    rows = [["kind", "name", "distribution", "status", "description"]]
    rows += [[spec.kind.value, spec.name, spec.distribution, plugin_status(spec, full).text(),
              spec.description] for spec in host.registry.specs()]
    for name, reason in sorted(host.broken.items()):
        dist, _, why = reason.partition(": ")
        rows.append(["?", name, dist, f"broken: entry point failed to load: {why}", ""])
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["│ " + " │ ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " │"
             for row in rows]
    rule = "├" + "┼".join("─" * (w + 2) for w in widths) + "┤"
    return "\n".join(["nlosfw plugins", lines[0], rule, *lines[1:]]) + "\n"


def plugins_command(host: PluginHost, console: Console | None = None,
                    args: Sequence[str] = ()) -> int:
    """Run ``plugins [NAME | --check | --help]``; returns the exit status. Written to
    ``console`` (by default the terminal; the listing as plain text to its file)."""
    parsed = _parse(args)
    if parsed.name:
        from rich.console import Console

        return _show_one(host, parsed.name, console or Console())
    out = sys.stdout if console is None else console.file
    if parsed.help:
        out.write(USAGE + "\n")
        return 0
    out.write(plugins_table(host, full=parsed.check))
    if not parsed.check:
        out.write("Details of one plugin: python -m nlosfw plugins NAME; import every "
                  "plugin: python -m nlosfw plugins --check\n")
        return 0
    broken = [s for s in host.registry.specs() if plugin_status(s, True).state == "broken"]
    return BROKEN_EXIT_STATUS if broken or host.broken else 0


def plugin_details(spec: PluginSpec) -> list[RenderableType]:
    """What ``plugins NAME`` prints for ``spec`` (imports the plugin): rich renderables."""
    from rich.markup import escape

    status = plugin_status(spec, full=True)
    out: list[RenderableType] = [
        f"[bold]{spec.qualified_name}[/]  {escape(spec.description)}",
        f"  kind          {spec.kind.value} ({_how_selected(spec)})",
        f"  distribution  {spec.distribution} {_version(spec.distribution)}",
        f"  entry point   {spec.entry_point or '-'}",
        f"  factory       {escape(_describe(spec.factory))}",
        f"  status        {status.markup()}",
    ]
    options: tuple[OptionDoc, ...] = ()
    if status.state == "ok":
        options = option_docs(spec.config_class(), groups=True)
        out.append(_options_table(spec, options))
    else:
        out.append("  (options unavailable until the plugin imports)")
    out.append(_capabilities_text(spec))
    out.append(_plan_text(spec))
    out.append("[bold]example[/]")
    out.append(f"  {escape(example_command(spec, options))}")
    out.append(f"  python -m nlosfw.testing {spec.qualified_name}       # run its conformance "
               "checks")
    return out


def _how_selected(spec: PluginSpec) -> str:
    """How a run picks the plugin: its config group, or (capture formats) the file."""
    if spec.kind in RUN_KINDS:
        return f"select it with {spec.kind.value}={spec.name}"
    return f"detected from a file's content; force it with capture.format={spec.name}"


def example_command(spec: PluginSpec, options: Sequence[OptionDoc]) -> str:
    """A command that selects the plugin and sets one of its numeric options (a capture
    format: reads a file with it)."""
    if spec.kind not in RUN_KINDS:
        return f"python -m nlosfw capture.path=FILE capture.format={spec.name}"
    command = f"python -m nlosfw {spec.kind.value}={spec.name}"
    numeric = next((o for o in options if o.name not in ("seed", "device")
                    and o.type in ("int", "float") and o.default is not None), None)
    if numeric is not None:
        command += f" {spec.kind.value}.{numeric.name}={numeric.default}"
    return command


# --------------------------------------------------------------------------- helpers
def _show_one(host: PluginHost, name: str, console: Console) -> int:
    from rich.markup import escape

    if name in host.broken and not any(s.name == name for s in host.registry.specs()):
        console.print(f"[bold]{escape(name)}[/]: [red]broken: entry point failed to load: "
                      f"{escape(host.broken[name])}[/]")
        return BROKEN_EXIT_STATUS
    if name in ("none", "model:none") and not any(s.name == "none" for s in host.registry.specs()):
        console.print("[bold]model=none[/] is not a plugin: it runs no field model and images "
                      "only the capture (no split; shorthand: python -m nlosfw image FILE)",
                      highlight=False)
        return 0
    # a bare name several kinds use (lct: a capture format and an imager) shows each of them
    specs = ([s for s in host.registry.specs() if s.name == name] if ":" not in name
             else []) or [host.registry.find(name)]
    status = 0
    for spec in specs:
        for item in plugin_details(spec):
            console.print(item, highlight=False)
        if plugin_status(spec, full=True).state == "broken":
            status = BROKEN_EXIT_STATUS
    return status


def _options_table(spec: PluginSpec, options: Sequence[OptionDoc]) -> Table:
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=f"options ({spec.kind.value}.<option>=<value>)", title_justify="left",
                  box=None, pad_edge=False, title_style="bold")
    table.add_column("option", style="cyan", no_wrap=True)
    table.add_column("type")
    table.add_column("default")
    table.add_column("unit")
    table.add_column("description", overflow="fold")
    for o in options:
        table.add_row(o.name, escape(o.type), escape(_yaml(o.default)), escape(o.unit),
                      escape(o.summary or "(undocumented)"))
    return table


def _capabilities_text(spec: PluginSpec) -> str:
    from rich.markup import escape

    origin = {"registration": "declared", "class": "declared by its class",
              "defaults": "declares none: the kind's defaults"}[spec.capabilities_origin]
    meanings = CAPABILITIES.get(spec.kind.value, {})
    lines = [f"[bold]capabilities[/] ({origin})"]
    for capability in sorted(spec.capabilities, key=lambda c: c.value):
        lines.append(f"  {capability.value:<17} {escape(meanings.get(capability, ''))}")
    return "\n".join(lines)


def _plan_text(spec: PluginSpec) -> str:
    from rich.markup import escape

    from nlosfw.common.errors import NlosfwError
    from nlosfw.testing import check_plan

    try:
        plan = check_plan(spec)
    except NlosfwError as err:
        return f"[bold]conformance kit[/]: [red]{escape(str(err))}[/]"
    lines = [f"[bold]conformance kit[/]: {len(plan.applied)} checks apply, "
             f"{len(plan.skipped)} skipped"]
    lines += [f"  run   {escape(p.name)}" for p in plan.applied]
    lines += [f"  skip  {escape(p.name)}: {escape(p.skip_reason)}" for p in plan.skipped]
    return "\n".join(lines)


def _version(distribution: str) -> str:
    try:
        return version(distribution)
    except PackageNotFoundError:
        return "(version unknown: not an installed distribution)"


def _describe(factory: str | Callable[..., Any] | LazyFactory) -> str:
    if isinstance(factory, str):
        return factory
    paths = getattr(factory, "import_paths", lambda: ())()
    if paths:
        return f"{type(factory).__name__} ({', '.join(paths)})"
    return f"{getattr(factory, '__module__', '?')}:{getattr(factory, '__qualname__', factory)}"


def _yaml(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "[" + ", ".join(_yaml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_yaml(v)}" for k, v in value.items()) + "}"
    return str(value)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise ConfigError("", f"plugins: {message}; usage: python -m nlosfw plugins "
                              "[NAME | --check]")


def _parse(args: Sequence[str]) -> argparse.Namespace:
    parser = _Parser(prog="python -m nlosfw plugins", add_help=False, allow_abbrev=False)
    parser.add_argument("name", nargs="?")
    parser.add_argument("--check", action="store_true")
    parser.add_argument("--help", "-h", action="store_true")
    parsed = parser.parse_args(list(args))
    if parsed.name and parsed.check:
        parser.error("give NAME or --check, not both")
    return parsed
