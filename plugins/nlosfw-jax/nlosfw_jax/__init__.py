"""JAX field models for nlosfw: ``tanh_jax``, ``pe_jax`` and ``siren_jax``.

Importing this package does not import jax; :mod:`nlosfw_jax.models` does.
"""
