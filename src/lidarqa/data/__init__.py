"""Data bundled with lidarqa (see ``ATTRIBUTION.md`` beside this file)."""

from importlib import resources
from pathlib import Path

__all__ = ["demo_tile", "DEMO_TILE_ATTRIBUTION"]

DEMO_TILE_ATTRIBUTION = "IGN – LiDAR HD (Licence Ouverte / Etalab 2.0)"


def demo_tile() -> Path:
    """Path of the bundled IGN LiDAR HD urban tile (50 m × 50 m, strips 706 and 707)."""
    return Path(str(resources.files(__name__) / "test_data_77055_627755_LA93_IGN69.laz"))
