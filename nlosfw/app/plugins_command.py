"""``python -m nlosfw plugins``: a table of every registered plugin."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from nlosfw.plugins import PluginHost


def plugins_table(host: PluginHost) -> Table:
    """Kind, name, distribution, whether its dependencies import (else the pip command)."""
    table = Table(title="nlosfw plugins", title_justify="left")
    table.add_column("kind", style="cyan", no_wrap=True)
    table.add_column("name", style="bold")
    table.add_column("distribution")
    table.add_column("dependencies")
    table.add_column("description", overflow="fold")
    for spec in host.registry.specs():
        command = spec.install_command()
        status = f"[red]missing: {command}[/]" if command else "[green]ok[/]"
        table.add_row(spec.kind.value, spec.name, spec.distribution, status, spec.description)
    for name, reason in sorted(host.broken.items()):
        table.add_row("?", name, reason.split(":", 1)[0], "[red]failed to load[/]", reason)
    return table


def plugins_command(host: PluginHost, console: Console | None = None) -> int:
    """Print the table; exit status 0."""
    console = console or Console()
    console.print(plugins_table(host))
    return 0
