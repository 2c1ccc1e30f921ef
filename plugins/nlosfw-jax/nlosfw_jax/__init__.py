"""JAX backend of nlosfw's neural fields (equinox modules, optax's Adam), and the thesis
networks ``tanh_jax``, ``pe_jax`` and ``siren_jax``.

Importing this package does not import jax; :mod:`nlosfw_jax.backend`,
:mod:`nlosfw_jax.networks` and :mod:`nlosfw_jax.models` do.
"""
