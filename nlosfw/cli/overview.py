"""What a run prints before it starts: its choices, what differs from the defaults, its plan.

The full configuration is in the run directory (``config.yaml``, ``.hydra/``); the console
shows the selected scene and plugins, the options that differ from their defaults (a
plugin's from its config class, the run settings' from :class:`RunSettings`, the scene's
from the built-in scene of that name), and what the run will compute: how many field
models it fits and how many reconstructions it makes, and why.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from nlosfw.common.config import config_to_dict
from nlosfw.common.errors import NlosfwError
from nlosfw.common.text import console_text as escape
from nlosfw.pipeline.settings import NO_MODEL, SELECTOR_GROUPS, RunSettings
from nlosfw.plugins import PluginHost

#: The plugin groups in a run's config, in pipeline order.
PLUGIN_GROUPS = ("simulator", "transform", "model", "imager")

#: At most this many changed options are listed (the rest are counted).
MAX_CHANGES = 12


def changed_options(config: Mapping[str, Any], host: PluginHost) -> list[str]:
    """``dotted.option=value`` for every option that differs from its default."""
    out: list[str] = []
    for group in PLUGIN_GROUPS:
        node = dict(config.get(group) or {})
        name = str(node.pop("name", ""))
        out += _diff(group, node, _plugin_defaults(host, group, name))
    settings = {k: v for k, v in config.items()
                if k not in SELECTOR_GROUPS and k not in ("published", "compare")}
    out += _diff("", settings, config_to_dict(RunSettings()))
    for label, options in (config.get("compare") or {}).items():
        rest = dict(options)
        name = str(rest.pop("name", ""))
        out.append(f"compare.{label}.name={name}")
        out += _diff(f"compare.{label}", rest, _plugin_defaults(host, "model", name))
    if config.get("scene") is not None:
        scene = dict(config["scene"])
        out += _diff("scene", scene, _scene_defaults(str(scene.get("name", ""))))
    return out


def overview_lines(config: Mapping[str, Any], host: PluginHost, settings: RunSettings,
                   picked: Mapping[str, str]) -> list[str]:
    """The lines printed before a run (rich markup): the scene and plugins ``picked`` (the
    plan's choices, by group), changed options, the plan."""
    named = dict(picked)
    if settings.capture.path is not None:
        named = {"capture": str(settings.capture.path), **picked}
    lines = ["  " + " · ".join(f"{group} [bold]{escape(name)}[/]"
                               for group, name in named.items())]
    changes = changed_options(config, host)
    if changes:
        shown = changes[:MAX_CHANGES]
        more = f" … and {len(changes) - len(shown)} more" if len(changes) > len(shown) else ""
        lines.append("  changed from the defaults: " + escape(", ".join(shown) + more))
    else:
        lines.append("  every option at its default")
    if settings.published:
        titles = [table.title or name for name, table in settings.published.items()]
        lines.append("  compared with published numbers: " + escape("; ".join(titles)))
    plan = run_plan(picked, settings)
    lines.append("  plan: " + escape(plan[0]))
    lines += ["        " + escape(line) for line in plan[1:]]
    return lines


def field_sources(model: str, settings: RunSettings) -> dict[str, str]:
    """The field models a run fits, by source: ``model`` (unless it is ``interp``),
    ``interp`` and the ``compare`` labels, each with its plugin."""
    if model == NO_MODEL:
        return {}
    sources = {"model": model} if model != "interp" else {}
    sources["interp"] = "interp"
    for label, options in settings.compare.items():
        sources[label] = str(options.get("name"))
    return sources


def single_frequency_count(settings: RunSettings) -> int:
    """How many single-frequency images each field gets: one training frequency, and one
    held-out frequency when the split holds some out, up to the setting."""
    available = 1 if str(settings.split.spectral) == "none" else 2
    return min(settings.reconstruction.single_frequency_images, available)


def run_plan(picked: Mapping[str, str], settings: RunSettings) -> list[str]:
    """The stages the run performs and the models it fits (first line), then how many
    reconstructions it makes and why (second line, when it images)."""
    source = (f"read {settings.capture.path}" if settings.capture.path
              else f"simulate {picked['scene']} ({picked['simulator']})")
    parts = [source]
    if settings.runs("transform"):
        parts.append(f"phasor field ({picked['transform']})")
    sources = field_sources(picked["model"], settings)
    if settings.runs("fit") and sources:
        parts.append("fit " + ", ".join(dict.fromkeys(sources.values())))
    if settings.runs("predict") and sources:
        parts.append("predict")
    if not settings.runs("reconstruct"):
        return [" → ".join(parts) + f" (stop after {settings.last_stage})"]
    if not sources:  # model=none: the capture imaged alone
        parts.append(f"1 reconstruction ({picked['imager']})")
        return [" → ".join(parts), "= the capture's field [no field model: model=none]"]
    count_splitting = settings.split.count_splitting
    fields = {"true": ("half B's full scan (count splitting)" if count_splitting
                       else "the reference"),
              "raw": "the training samples"}
    if count_splitting:
        fields["ceiling"] = "half A's full scan"
    for label, plugin in sources.items():
        fields[label] = "the baseline" if label == "interp" else plugin
    singles = single_frequency_count(settings)
    total = len(fields) * (1 + singles)
    parts.append(f"{total} reconstructions ({picked['imager']})")
    why = ", ".join(f"{label}: {reason}" for label, reason in fields.items())
    frequencies = "all frequencies" + {0: "", 1: " + 1 single frequency (training)",
                                       2: " + 2 single frequencies (training, held out)"
                                       }[singles]
    return [" → ".join(parts), f"= {len(fields)} fields [{why}] × ({frequencies})"]


# --------------------------------------------------------------------------- helpers
def _plugin_defaults(host: PluginHost, group: str, name: str) -> dict[str, Any]:
    try:
        return config_to_dict(host.registry.get(group, name).make_config({}))
    except (NlosfwError, TypeError):
        return {}


def _scene_defaults(name: str) -> dict[str, Any]:
    from nlosfw.simulate.builtin_scenes import builtin_scene, builtin_scene_names

    if name not in builtin_scene_names():
        return {}
    try:
        return config_to_dict(builtin_scene(name))
    except NlosfwError:
        return {}


def _diff(prefix: str, values: Mapping[str, Any], defaults: Mapping[str, Any]) -> list[str]:
    out = []
    for key, value in values.items():
        dotted = f"{prefix}.{key}" if prefix else str(key)
        default = defaults.get(key, _MISSING)
        if isinstance(value, Mapping) and isinstance(default, Mapping) and value:
            out += _diff(dotted, value, default)
        elif _normal(value) != _normal(default):
            out.append(f"{dotted}={_short(value)}")
    return out


_MISSING = object()


def _normal(value: Any) -> Any:
    if isinstance(value, (list, tuple)):
        return [_normal(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _normal(v) for k, v in value.items()}
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def _short(value: Any, limit: int = 40) -> str:
    if isinstance(value, Sequence) and not isinstance(value, str) and value and all(
            isinstance(v, Mapping) for v in value):
        return f"[{len(value)} items]"
    if isinstance(value, str):
        return value                      # paths and names in full
    text = "null" if value is None else str(value).lower() if isinstance(value, bool) \
        else str(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"
