"""Shim so ``python cli.py scene.json`` works from a checkout; the entry point is
``pathtracer.cli:main`` (installed as the ``pt-render`` command)."""
import sys

from pathtracer.cli import main

if __name__ == "__main__":
    sys.exit(main())
