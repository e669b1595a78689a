"""The former name of `bench/telemetry.py` (kept so that existing commands keep working)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.telemetry import main

if __name__ == "__main__":
    sys.exit(main())
