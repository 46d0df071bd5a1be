"""python -m bench: the batch benchmark (see bench/run.py)."""
import sys

from bench.run import main

sys.exit(main())
