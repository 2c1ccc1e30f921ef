"""Whether JAX can use a device on this machine, asked before a run without using it.

Asked for one platform's devices, JAX sets up every platform it has, and on a GPU takes
most of its memory for itself (XLA's preallocation) for as long as the process lives: a
sweep's parent process checking its jobs' configuration would keep it from the workers
that run them. So the devices are counted in a short-lived process of their own, with
the preallocation turned off; ``auto`` and ``cpu`` need no count (XLA always has a CPU).
"""

from __future__ import annotations

import os
import subprocess
import sys

from nlosfw.common import ConfigError

#: What the counting process runs: the number of devices of the platform ``argv[1]``.
_COUNT = "import sys, jax; print(len(jax.devices(sys.argv[1])))"
#: [s] How long counting may take (importing JAX and setting up its platforms).
_TIMEOUT = 300
_VALID = "valid: auto, cpu, gpu, gpu:N"


def check_device(name: str) -> None:
    """A ConfigError for ``model.device`` unless JAX has device ``name`` (``gpu:1``,
    ``cuda:0``, ``tpu``, ...) on this machine."""
    if name in ("auto", "cpu"):
        return
    platform, _, index = name.partition(":")
    platform = {"cuda": "gpu"}.get(platform, platform)
    if not platform or (index and not index.isdigit()):
        raise ConfigError("model.device", f"JAX does not know device {name!r}; {_VALID}")
    count, reason = _count(platform)
    if int(index or 0) >= count:
        seen = reason or (f"it sees {count or 'no'} {platform} device"
                          f"{'' if count == 1 else 's'} on this machine")
        raise ConfigError("model.device", f"JAX cannot use device {name!r} ({seen}); {_VALID}")


def _count(platform: str) -> tuple[int, str]:
    """The number of ``platform``'s devices JAX sees, and why it sees none when it cannot
    tell (its error's last line)."""
    env = {**os.environ, "XLA_PYTHON_CLIENT_PREALLOCATE": "false"}
    try:
        done = subprocess.run([sys.executable, "-c", _COUNT, platform], env=env,
                              capture_output=True, text=True, timeout=_TIMEOUT, check=False)
    except (OSError, subprocess.TimeoutExpired) as err:
        return 0, f"counting its devices failed: {err}"
    if done.returncode == 0 and done.stdout.strip().isdigit():
        return int(done.stdout.strip()), ""
    lines = [line.strip() for line in done.stderr.splitlines() if line.strip()]
    return 0, lines[-1] if lines else f"counting its devices ended with status {done.returncode}"
