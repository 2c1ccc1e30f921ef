"""nlosfw's configs in Hydra: the ConfigStore entries, the resolvers, Hydra's compose API.

1. The run's schema (:class:`~nlosfw.pipeline.settings.RunConfig`) and one config group
   entry per registered plugin (``model=siren_torch``), made from the plugin's own config
   dataclass, go into Hydra's ConfigStore: Hydra checks every name and type as it
   composes, and a third-party plugin is selectable without touching ``conf/``;
2. ``+group=name`` is accepted for the selector groups (``+simulator=embree``): Hydra
   refuses ``+`` for a group that already has a default, so the ``+`` is dropped there and
   the override selects the option as ``group=name`` does.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from nlosfw.common.errors import NlosfwError, one_line
from nlosfw.common.resources import config_dir
from nlosfw.common.schema import schema_class
from nlosfw.pipeline.settings import SELECTOR_GROUPS, RunConfig
from nlosfw.plugins import RUN_KINDS, PluginHost

log = logging.getLogger(__name__)

#: Name of the run's schema in Hydra's ConfigStore (the first entry of config.yaml's defaults).
RUN_SCHEMA = "nlosfw_run_schema"


def register_configs(host: PluginHost) -> None:
    """Store the run's schema and one entry per plugin of the kinds a run selects (group =
    plugin kind) in Hydra's ConfigStore; a plugin's entry is its config dataclass with the
    selector ``name``. Capture formats are chosen by ``capture.format`` instead."""
    from hydra.core.config_store import ConfigStore
    from omegaconf.errors import OmegaConfBaseException

    store = ConfigStore.instance()
    store.store(name=RUN_SCHEMA, node=schema_class(RunConfig), provider="nlosfw")
    for spec in host.registry.specs():
        if spec.kind not in RUN_KINDS:
            continue
        try:
            cls = spec.config_class()
            if "name" in {f.name for f in dataclasses.fields(cls)}:
                log.warning("plugin %s is not selectable: its config has a field 'name', which "
                            "is the group's plugin selector", spec.qualified_name)
                continue
            store.store(group=spec.kind.value, name=spec.name,
                        node=schema_class(cls, spec.name), provider=spec.distribution)
        except (NlosfwError, OmegaConfBaseException, TypeError) as err:
            log.warning("plugin %s has no usable config and is not selectable: %s",
                        spec.qualified_name, one_line(err))


def ensure_resolvers() -> None:
    """Register the ``nlosfw_run_id`` resolver (a short random id, fixed per process)."""
    from omegaconf import OmegaConf

    if not OmegaConf.has_resolver("nlosfw_run_id"):
        run_id = uuid.uuid4().hex[:6]
        OmegaConf.register_new_resolver("nlosfw_run_id", lambda: run_id)


def normalise_overrides(args: Sequence[str]) -> list[str]:
    """Turn ``+group=x`` / ``++group=x`` into ``group=x`` for the selector groups."""
    out = []
    for arg in args:
        stripped = arg.lstrip("+")
        key = stripped.split("=", 1)[0]
        if arg.startswith("+") and "=" in stripped and key in SELECTOR_GROUPS:
            out.append(stripped)
        else:
            out.append(arg)
    return out


#: Held by :func:`hydra_session`: Hydra's ConfigStore and its global session are shared by
#: every thread of the process, so threads (``nlosfw.run`` called from two at once) take
#: turns composing; the runs themselves go on in parallel.
SESSION_LOCK = threading.RLock()


@contextmanager
def hydra_session() -> Iterator[None]:
    """Hydra's compose API ready over nlosfw's configs: the running app's (a check inside
    ``hydra.main``), else a session of its own, ended with the block; one thread at a time
    (:data:`SESSION_LOCK`)."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    with SESSION_LOCK:
        if GlobalHydra.instance().is_initialized():
            yield
            return
        with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3",
                                   job_name="nlosfw"):
            yield
