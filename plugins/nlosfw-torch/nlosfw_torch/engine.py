"""Deprecated: the torch backend is :mod:`nlosfw_torch.backend` (this module goes in nlosfw
0.3). Importing it warns; its names are the backend's (``TorchEngine`` is
:class:`~nlosfw_torch.backend.TorchBackend`)."""

from __future__ import annotations

import warnings

from nlosfw_torch.backend import DEFAULT_THREADS, TorchBackend, resolve_device

warnings.warn("nlosfw_torch.engine is deprecated and will be removed in nlosfw 0.3: use "
              "nlosfw_torch.backend (TorchEngine is now TorchBackend)", DeprecationWarning,
              stacklevel=2)

TorchEngine = TorchBackend

__all__ = ["DEFAULT_THREADS", "TorchBackend", "TorchEngine", "resolve_device"]
