"""An example third-party nlosfw plugin."""
