"""Example third-party nlosfw network: a Fourier-feature MLP (``model=example_fourier_torch``)."""
