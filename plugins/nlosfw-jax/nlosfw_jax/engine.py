"""Deprecated: the JAX backend is :mod:`nlosfw_jax.backend` (this module goes in nlosfw
0.3). Importing it warns; its names are the backend's (``JaxEngine`` is
:class:`~nlosfw_jax.backend.JaxBackend`)."""

from __future__ import annotations

import warnings

from nlosfw_jax.backend import Fixed, JaxBackend, resolve_device

warnings.warn("nlosfw_jax.engine is deprecated and will be removed in nlosfw 0.3: use "
              "nlosfw_jax.backend (JaxEngine is now JaxBackend)", DeprecationWarning,
              stacklevel=2)

JaxEngine = JaxBackend

__all__ = ["Fixed", "JaxBackend", "JaxEngine", "resolve_device"]
