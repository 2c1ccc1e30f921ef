"""PyTorch field models for nlosfw: ``tanh_torch``, ``pe_torch`` and ``siren_torch``.

Importing this package does not import torch; :mod:`nlosfw_torch.models` does.
"""
