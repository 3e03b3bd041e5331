"""The real GFS file the GRIB tests read (../shared/data/grib/, its README lists the fields)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest

NAME = "gfs.t12z.pgrbf120.2p5deg.grib2"
# The copy kept in the repository (tests/data/grib/README.md), and the shared original
GFS = Path(__file__).resolve().parent / "data" / "grib" / NAME
SHARED_GFS = Path(__file__).resolve().parents[2] / "shared" / "data" / "grib" / NAME
VALID = datetime(2011, 1, 15, 12, tzinfo=UTC)  # run 2011-01-10 12Z + 120 h: its one step
LONDON = (51.5, -0.1)
needs_gfs = pytest.mark.skipif(not GFS.exists(), reason=f"the GFS fixture is absent: {GFS}")
