"""``python -m nlosfw``."""

from nlosfw.cli import main

raise SystemExit(main())
