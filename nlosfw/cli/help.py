"""``python -m nlosfw --help``: one short page instead of Hydra's raw dump.

The page lists the subcommands, the config groups with what each holds (the scenes,
presets and installed plugins to choose from; the settings groups' one-line
documentation comes from :class:`~nlosfw.pipeline.settings.RunSettings` itself), five example
commands and where the documentation is. Hydra's own help stays at ``--hydra-help``.
"""

from __future__ import annotations

import dataclasses
import textwrap
from pathlib import Path
from typing import get_type_hints

from nlosfw.common.config_docs import attribute_docstrings, first_sentence, option_docs
from nlosfw.common.version import __version__
from nlosfw.pipeline.settings import NO_MODEL, RunSettings
from nlosfw.plugins import PluginHost

SUBCOMMANDS = (
    ("python -m nlosfw [OVERRIDE ...]", "one run: simulate or read a capture, fit, image, "
                                        "report"),
    ("python -m nlosfw -m OVERRIDE ...", "a sweep: every combination of comma-separated "
                                         "values"),
    ("python -m nlosfw image FILE ...", "image one capture, no field model (views, "
                                        "report.html)"),
    ("python -m nlosfw plugins [NAME]", "installed plugins; NAME: its options, capabilities, "
                                        "checks"),
    ("python -m nlosfw plugins --check", "import every plugin; broken ones say why"),
    ("python -m nlosfw report DIR", "tables and plots of the runs under DIR (a sweep)"),
    ("python -m nlosfw cache info", "the cache's entries and sizes (cache clean [--keep-gb N] "
                                    "evicts)"),
    ("python -m nlosfw -cn NAME -m", "a sweep preset: {primary}"),
    ("python -m nlosfw.testing NAME", "the conformance kit on a plugin (--plan: which "
                                      "checks)"),
)

#: Width the page is wrapped to.
WIDTH = 100

#: What each selector group chooses (its options are listed from the installation).
SELECTOR_DOCS = {
    "scene": "the hidden scene, wall and time axis (scene.<option>=... changes one)",
    "simulator": "renders the scene into a transient capture",
    "transform": "turns the capture into a phasor field",
    "model": "the field model fitted to the sparse field (interp is the baseline; none fits "
             "none, the capture is imaged alone)",
    "imager": "reconstructs the hidden volume from a phasor field",
    "capture_format": "reads capture.path, detected from the file's content "
                      "(capture.format=NAME forces one)",
    "acquisition": "how a study captures its scenes (clean: analytic, noise-free; noisy: "
                   "embree with Poisson noise)",
    "sampling": "the scan pattern of a sparse scan",
    "experiment": "a preset (thesis figures, the noise and sparsity studies)",
}

#: Five commands a new user can run as they are (the tests compose each one).
EXAMPLES = (
    ("python -m nlosfw", "the default run: two planes, SIREN vs interp, minutes on a CPU"),
    ("python -m nlosfw scene=thesis_occluded simulator=embree model=siren_jax",
     "a ray-traced scene with shadows, the JAX SIREN"),
    ("python -m nlosfw model=interp +compare.siren={name:siren_torch,steps:500}",
     "two field models imaged side by side"),
    ("python -m nlosfw -m model=siren_torch,tanh_torch,interp scene=thesis_planes",
     "a sweep over models (then: python -m nlosfw report multirun/...)"),
    ("python -m nlosfw experiment=thesis_fig4_4 output.keep=[model,reconstructions]",
     "a thesis preset, keeping the model and the reconstructions"),
)

MORE = (
    ("python -m nlosfw --cfg job ...", "print the composed configuration and stop"),
    ("python -m nlosfw --debug ...", "tracebacks for errors"),
    ("python -m nlosfw --hydra-help", "Hydra's own help (flags, --info, shell completion)"),
)

DOCS = "README.md, docs/index.md (mkdocs serve), CONTRIBUTING.md in the source repository"


def help_text(host: PluginHost, conf: Path) -> str:
    """The help page; ``conf`` is the directory of Hydra's ``config.yaml``."""
    primary = sorted(p.stem for p in conf.glob("*.yaml") if p.stem != "config")
    scenes = sorted(p.stem for p in (conf / "scene").glob("*.yaml"))
    defaults = _selected_defaults(conf / "config.yaml")
    lines = [f"nlosfw {__version__}: non-line-of-sight imaging with implicit neural phasor "
             "fields", "", "usage"]
    lines += _rows([(cmd, what.format(primary=", ".join(primary)))
                    for cmd, what in SUBCOMMANDS])
    lines += ["", "config groups (group=name selects, group.option=value sets an option;",
              "python -m nlosfw plugins NAME lists a plugin's options)"]
    groups = []
    for group, what in SELECTOR_DOCS.items():
        if group in ("experiment", "acquisition", "sampling"):
            names = sorted(p.stem for p in (conf / group).glob("*.yaml"))
        elif group == "scene":
            names = scenes
        else:
            names = host.registry.names(group)
        if group == "model":
            names = [*names, NO_MODEL]
        default = defaults.get(group)
        shown = [f"{n} (default)" if n == default else n for n in names]
        groups.append((group, f"{what}: {', '.join(shown) or '(none installed)'}"))
    docs = attribute_docstrings(RunSettings)
    hints = get_type_hints(RunSettings)
    for f in dataclasses.fields(RunSettings):
        if f.name == "published":     # published numbers: the presets set them
            continue
        summary = first_sentence(docs.get(f.name, "")).rstrip(".")
        summary = summary[:1].lower() + summary[1:]
        tp = hints[f.name]
        options = (", ".join(o.name for o in option_docs(tp))
                   if isinstance(tp, type) and dataclasses.is_dataclass(tp) else "")
        name = f"{f.name}.*" if options else f.name
        groups.append((name, f"{summary}" + (f" ({options})" if options else "")))
    lines += _rows(groups)
    lines += ["", "examples"]
    for command, what in EXAMPLES:
        lines += [f"  # {what}", f"  {command}"]
    lines += ["", "more"]
    lines += _rows(list(MORE))
    lines += [""] + textwrap.wrap(f"documentation: {DOCS}", width=WIDTH)
    return "\n".join(lines)


def _selected_defaults(config_yaml: Path) -> dict[str, str]:
    """``group: name`` entries of config.yaml's defaults list."""
    import yaml

    data = yaml.safe_load(config_yaml.read_text(encoding="utf-8")) or {}
    out = {}
    for entry in data.get("defaults", []):
        if isinstance(entry, dict) and len(entry) == 1:
            ((group, name),) = entry.items()
            out[str(group)] = str(name)
    return out


def _rows(rows: list[tuple[str, str]], width: int = WIDTH) -> list[str]:
    """Two columns, the right one wrapped to ``width`` with a hanging indent."""
    left_width = max(len(left) for left, _ in rows) + 2
    out = []
    for left, right in rows:
        wrapped = textwrap.wrap(right, width=max(30, width - left_width - 2),
                                break_on_hyphens=False) or [""]
        out.append(f"  {left:<{left_width}}{wrapped[0]}")
        out += [" " * (left_width + 2) + line for line in wrapped[1:]]
    return out
