"""An example third-party nlosfw imager: phasor-field backprojection."""
