"""The light, numpy-only plugins shipped with the core."""
