"""Acceptance profiles: the limits a delivery is checked against, each with its source.

Four built-in profiles follow the USGS Lidar Base Specification (LBS, 2024 rev. A) quality
levels QL0-QL3 and the ASPRS Positional Accuracy Standards for Digital Geospatial Data,
Edition 2 (2023). Every limit carries the section of the document it comes from
(:attr:`QCSpec.sources`), shown in the report beside the verdict. A TOML file of one's
own limits starts from a built-in profile (``base = "usgs-ql2"``) and overrides keys::

    base = "usgs-ql2"
    name = "county-2025"
    min_anpd = 4.0                      # first returns per m²
    allowed_classes = [1, 2, 6, 7, 9, 17, 18]
    [sources]
    min_anpd = "County RFP 2025, section 3.2"

The section and table titles are those of the LBS online table of contents (Collection;
Data Processing and Handling; Tables 1-5, absolute vertical accuracy being Table 4 and
land cover Table 3). A citation marked "value not checked" names a section that exists
but whose number was not verified against the 2024 rev. A text; one marked "not
verified" could not be located. Check the limits against the edition your contract names
(the online edition is revised yearly).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from ..accuracy.swaths import QUALITY_LEVELS
from ..errors import ConfigError, OptionError

__all__ = ["QCSpec", "PROFILES", "get_spec", "load_spec", "spec_names", "LAS_CLASS_NAMES"]

_LBS = "USGS Lidar Base Specification 2024 rev. A"
_ASPRS = "ASPRS Positional Accuracy Standards Ed. 2 (2023)"

#: ASPRS LAS 1.4 R15 standard classes (PDRF 6-10), Table 17.
LAS_CLASS_NAMES: dict[int, str] = {
    0: "created, never classified",
    1: "unclassified",
    2: "ground",
    3: "low vegetation",
    4: "medium vegetation",
    5: "high vegetation",
    6: "building",
    7: "low point (noise)",
    8: "reserved",
    9: "water",
    10: "rail",
    11: "road surface",
    12: "reserved (overlap in PDRF 0-5)",
    13: "wire - guard",
    14: "wire - conductor",
    15: "transmission tower",
    16: "wire - structure connector",
    17: "bridge deck",
    18: "high noise",
    19: "overhead structure",
    20: "ignored ground",
    21: "snow",
    22: "temporal exclusion",
}

# LBS: classes 1, 2, 7, 9, 17, 18, 20, 21, 22 are the minimum scheme; additional ASPRS
# classes and user classes (64-255) may be used; class 0 must not remain, and no class may
# mark overage (overlap) points (class 12): the overlap flag does.
_LBS_ALLOWED = tuple([1, 2, 3, 4, 5, 6, 7, 9, 10, 11] + list(range(13, 23)) + list(range(64, 256)))


@dataclass(frozen=True)
class QCSpec:
    """The limits of one acceptance profile.

    Attributes
    ----------
    name : str
        ``"usgs-ql2"``, or the name given in a TOML file.
    title : str
    las_versions : tuple of str
        LAS versions accepted (e.g. ``("1.4",)``).
    point_formats : tuple of int
        Point data record formats accepted.
    require_wkt : bool
        The CRS must be stored as OGC WKT (global encoding WKT bit and a WKT VLR).
    require_vertical_crs : bool
        The CRS must include a vertical datum (compound CRS).
    gps_time_type : str or None
        ``"adjusted standard"`` (global encoding bit 0), or None for no check.
    min_anpd : float
        Aggregate nominal pulse density, first returns per m² (single swath).
    min_spatial_distribution : float
        Share (0-1) of 2 x ANPS cells holding at least one first return.
    void_factor : float
        A void is an area of at least ``(void_factor x ANPS)²`` without first returns.
    max_void_area_m2 : float
        Void area (m²) a tile may hold before it fails (0: any void fails).
    allowed_classes : tuple of int
        Classification codes allowed.
    max_duplicates : int
        Duplicate point records (same X, Y, Z and GPS time) a tile may hold.
    max_nva_rmse_m : float
        Non-vegetated vertical accuracy, RMSEz at check points (m).
    min_checkpoints : int
        Fewest check points for an NVA verdict.
    max_intraswath_m : float
        Smooth-surface precision (intraswath), m.
    max_swath_rmsdz_m : float
        Swath overlap difference, RMSDz (m).
    max_swath_abs_dz_m : float
        Swath overlap difference, largest absolute dz of the per-cell differences (m).
    max_scan_angle_deg : float or None
        Largest absolute scan angle (degrees); None: only the LAS range is checked.
    density_cell_m : float or None
        Cell of the density raster and of the ANPD sum (m); default 8 x ANPS.
    sources : dict
        Limit name -> the document section it comes from.
    """

    name: str
    title: str
    las_versions: tuple[str, ...] = ("1.4",)
    point_formats: tuple[int, ...] = (6, 7, 8, 9, 10)
    require_wkt: bool = True
    require_vertical_crs: bool = True
    gps_time_type: str | None = "adjusted standard"
    min_anpd: float = 2.0
    min_spatial_distribution: float = 0.90
    void_factor: float = 4.0
    max_void_area_m2: float = 0.0
    allowed_classes: tuple[int, ...] = _LBS_ALLOWED
    max_duplicates: int = 0
    max_nva_rmse_m: float = 0.10
    min_checkpoints: int = 30
    max_intraswath_m: float = 0.06
    max_swath_rmsdz_m: float = 0.08
    max_swath_abs_dz_m: float = 0.16
    max_scan_angle_deg: float | None = None
    density_cell_m: float | None = None
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def anps(self) -> float:
        """Aggregate nominal pulse spacing, m (``1 / sqrt(min_anpd)``)."""
        return 1.0 / math.sqrt(self.min_anpd)

    @property
    def distribution_cell_m(self) -> float:
        """Cell of the spatial-distribution grid: 2 x ANPS, m."""
        return 2.0 * self.anps

    @property
    def void_side_m(self) -> float:
        """Side of the smallest void: ``void_factor x ANPS``, m."""
        return self.void_factor * self.anps

    @property
    def density_cell(self) -> float:
        """Cell of the density raster, m (``density_cell_m`` or 8 x ANPS, 4 distribution cells)."""
        return float(self.density_cell_m or 4.0 * self.distribution_cell_m)

    def source(self, key: str) -> str:
        """The document section a limit comes from ("" when none is recorded)."""
        return self.sources.get(key, "")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the limits and their sources."""
        d = asdict(self)
        d["las_versions"] = list(self.las_versions)
        d["point_formats"] = list(self.point_formats)
        d["allowed_classes"] = _ranges(self.allowed_classes)
        d["anps_m"] = self.anps
        d["distribution_cell_m"] = self.distribution_cell_m
        d["void_side_m"] = self.void_side_m
        d["density_cell_m"] = self.density_cell
        return d


def _ranges(codes: tuple[int, ...]) -> str:
    """``(1, 2, 3, 5)`` -> ``"1-3, 5"``."""
    out: list[str] = []
    cs = sorted(set(int(c) for c in codes))
    i = 0
    while i < len(cs):
        j = i
        while j + 1 < len(cs) and cs[j + 1] == cs[j] + 1:
            j += 1
        out.append(str(cs[i]) if i == j else f"{cs[i]}-{cs[j]}")
        i = j + 1
    return ", ".join(out)


#: Appended to a citation whose section was found in the LBS online table of contents but
#: whose wording or value was not checked against the 2024 rev. A text.
_UNCHECKED = " [section verified; value not checked against the 2024 rev. A text]"
#: Appended to a citation whose section could not be located either.
_UNVERIFIED = " [not verified against the LBS text]"


def _lbs_sources() -> dict[str, str]:
    # Section and table titles checked (Nov 2026) against the LBS online table of contents
    # (usgs.gov "Lidar Base Specification Online: Table of Contents": Collection; Data
    # Processing and Handling; Tables 1 aggregate nominal pulse spacing and density,
    # 2 relative vertical accuracy for swath data, 3 land cover classes, 4 absolute
    # vertical accuracy, 5 minimum classification scheme) and the v2.1 section list
    # (Nominal Pulse Spacing, Data Voids, Spatial Distribution and Regularity, LAS File
    # Format, Time of GPS Data, Coordinate Reference System / Well-Known Text, Relative
    # Vertical Accuracy, Absolute Vertical Accuracy, Point Classification, Point
    # Duplication). The numbers in the tables were not readable there: see _UNCHECKED.
    return {
        "las_versions": f"{_LBS}, Data Processing and Handling: ASPRS LAS File Format "
        "(LAS 1.4-R15)",
        "point_formats": f"{_LBS}, Data Processing and Handling: ASPRS LAS File Format "
        "(point data record format 6-10)" + _UNCHECKED,
        "require_wkt": f"{_LBS}, Data Processing and Handling: Coordinate Reference System, "
        "Well-Known Text (horizontal and vertical CRS as OGC WKT)",
        "require_vertical_crs": f"{_LBS}, Data Processing and Handling: Coordinate Reference "
        "System, Well-Known Text",
        "gps_time_type": f"{_LBS}, Data Processing and Handling: Time of Global Positioning "
        "System Data (Adjusted Standard GPS time)" + _UNCHECKED,
        "min_anpd": f"{_LBS}, Collection: Nominal Pulse Spacing, Table 1 (ANPD assessed on "
        "single swath, first return data)",
        "min_spatial_distribution": f"{_LBS}, Collection: Spatial Distribution and Regularity "
        "(2 x ANPS grid, 90 % of cells with a first return)" + _UNCHECKED,
        "void_factor": f"{_LBS}, Collection: Data Voids ((4 x ANPS)² without first returns, "
        "water excepted)" + _UNCHECKED,
        "max_void_area_m2": f"{_LBS}, Collection: Data Voids" + _UNCHECKED,
        "allowed_classes": f"{_LBS}, Data Processing and Handling: Point Classification, "
        "Table 5 (minimum classification scheme; overage by the overlap bit flag, not a "
        "class code)" + _UNCHECKED,
        "max_duplicates": f"{_LBS}, Data Processing and Handling: Point Duplication"
        + _UNCHECKED,
        "max_nva_rmse_m": f"{_LBS}, Data Processing and Handling: Absolute Vertical Accuracy, "
        f"Table 4 (NVA RMSEz){_UNCHECKED}; {_ASPRS}" + _UNVERIFIED,
        "min_checkpoints": f"{_ASPRS} (at least 30 check points for a vertical accuracy "
        "test)" + _UNVERIFIED,
        "max_intraswath_m": f"{_LBS}, Data Processing and Handling: Relative Vertical "
        "Accuracy, Intraswath Precision, Table 2 (smooth surface repeatability)" + _UNCHECKED,
        "max_swath_rmsdz_m": f"{_LBS}, Data Processing and Handling: Relative Vertical "
        "Accuracy, Interswath (Overlap) Consistency, Table 2 (swath overlap difference, "
        "RMSDz)" + _UNCHECKED,
        "max_swath_abs_dz_m": f"{_LBS}, Data Processing and Handling: Relative Vertical "
        "Accuracy, Interswath (Overlap) Consistency, Table 2 (swath overlap difference, "
        "maximum)" + _UNCHECKED,
    }


def _ql(name: str, level: str, anpd: float, nva: float, intra: float, rmsdz: float,
        maxdz: float) -> QCSpec:
    return QCSpec(
        name=name,
        title=f"USGS LBS {level}",
        min_anpd=anpd,
        max_nva_rmse_m=nva,
        max_intraswath_m=intra,
        max_swath_rmsdz_m=rmsdz,
        max_swath_abs_dz_m=maxdz,
        sources=_lbs_sources(),
    )


#: The built-in profiles by name.
PROFILES: dict[str, QCSpec] = {
    "usgs-ql0": _ql("usgs-ql0", "QL0", 8.0, 0.05, *QUALITY_LEVELS["QL0"]),
    "usgs-ql1": _ql("usgs-ql1", "QL1", 8.0, 0.10, *QUALITY_LEVELS["QL1"]),
    "usgs-ql2": _ql("usgs-ql2", "QL2", 2.0, 0.10, *QUALITY_LEVELS["QL2"]),
    "usgs-ql3": _ql("usgs-ql3", "QL3", 0.5, 0.20, *QUALITY_LEVELS["QL3"]),
}


def spec_names() -> list[str]:
    """Names of the built-in profiles."""
    return sorted(PROFILES)


def get_spec(spec: str | os.PathLike | QCSpec) -> QCSpec:
    """A profile by name (``"usgs-ql2"``), from a TOML file, or as given.

    Raises
    ------
    OptionError
        An unknown name (the message lists the built-in ones).
    ConfigError
        A TOML file with unknown keys or values of the wrong type.
    """
    if isinstance(spec, QCSpec):
        return spec
    s = os.fspath(spec)
    if s.lower() in PROFILES:
        return PROFILES[s.lower()]
    if s.lower().endswith(".toml"):
        return load_spec(s)
    raise OptionError(
        f"unknown spec {s!r}: use one of {', '.join(spec_names())} or a .toml file of limits"
    )


_TUPLES = {"las_versions": str, "point_formats": int, "allowed_classes": int}


def load_spec(path: str | os.PathLike) -> QCSpec:
    """Read a profile of one's own limits from TOML (see the module documentation)."""
    import tomllib

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"spec file {p} does not exist")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"spec file {p} is not valid TOML: {exc}") from exc
    base_name = str(data.pop("base", "usgs-ql2")).lower()
    if base_name not in PROFILES:
        raise ConfigError(f"spec file {p}: unknown base {base_name!r} "
                          f"(use one of {', '.join(spec_names())})")
    base = PROFILES[base_name]
    known = {f.name: f for f in fields(QCSpec)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(f"spec file {p}: unknown key(s) {', '.join(unknown)} "
                          f"(known: {', '.join(sorted(known))})")
    changes: dict[str, Any] = {}
    for k, v in data.items():
        try:
            if k in _TUPLES:
                if not isinstance(v, list):
                    raise TypeError("a list")
                changes[k] = tuple(_TUPLES[k](x) for x in v)
            elif k == "sources":
                if not isinstance(v, dict):
                    raise TypeError("a table")
                changes[k] = {**base.sources, **{str(a): str(b) for a, b in v.items()}}
            elif k in ("name", "title", "gps_time_type"):
                changes[k] = None if (k == "gps_time_type" and v in ("", "none")) else str(v)
            elif k in ("require_wkt", "require_vertical_crs"):
                if not isinstance(v, bool):
                    raise TypeError("true or false")
                changes[k] = v
            elif k in ("max_duplicates", "min_checkpoints"):
                if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                    raise TypeError("an integer >= 0")
                changes[k] = int(v)
            else:
                if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                        or v < 0:
                    raise TypeError("a number >= 0")
                changes[k] = float(v)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"spec file {p}: {k} must be {exc}") from None
    if changes.get("min_anpd", base.min_anpd) <= 0:
        raise ConfigError(f"spec file {p}: min_anpd must be > 0")
    own: dict[str, Any] = data["sources"] if isinstance(data.get("sources"), dict) else {}
    srcs = {**base.sources, **{str(a): str(b) for a, b in own.items()}}
    for k in data:
        if k not in ("sources", "name", "title") and k not in own:
            srcs[k] = f"{p.name} (own limit)"
    changes["sources"] = srcs
    changes.setdefault("name", p.stem)
    changes.setdefault("title", f"{changes['name']} (from {base.title})")
    return replace(base, **changes)
