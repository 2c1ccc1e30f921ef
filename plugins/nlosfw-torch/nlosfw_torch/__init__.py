"""PyTorch backend of nlosfw's neural fields: any ``torch.nn.Module`` as a field model,
and the thesis networks ``tanh_torch``, ``pe_torch`` and ``siren_torch``.

Importing this package does not import torch; :mod:`nlosfw_torch.backend`,
:mod:`nlosfw_torch.networks` and :mod:`nlosfw_torch.models` do.
"""
