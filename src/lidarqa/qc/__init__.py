"""Delivery acceptance: the point-cloud checks of the USGS LBS and ASPRS Ed. 2 per tile.

- :mod:`~lidarqa.qc.profiles`: the QL0-QL3 profiles (every limit with its source) and a
  TOML loader of one's own limits;
- :mod:`~lidarqa.qc.conformance`: header and point checks in one streaming pass;
- :mod:`~lidarqa.qc.density`: ANPD (first returns, single swath), spatial distribution,
  density raster;
- :mod:`~lidarqa.qc.voids`: voids of (4 x ANPS)² and more, minus water;
- :mod:`~lidarqa.qc.classification`: confusion matrix against a reference;
- :func:`run_qc`: the whole run over a delivery (any input :func:`lidarqa.tiling.open_catalog`
  takes), on the tiling engine.
"""

from .conformance import Check
from .profiles import PROFILES, QCSpec, get_spec, load_spec, spec_names
from .run import QCResult, TileReport, run_qc

__all__ = ["Check", "PROFILES", "QCSpec", "get_spec", "load_spec", "spec_names", "QCResult",
           "TileReport", "run_qc"]
