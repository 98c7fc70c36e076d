"""Names used in the annotations of ``lidarqa.tiling`` (types only, nothing at run time).

Import them under ``if TYPE_CHECKING:``; the aliases are strings at run time.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import TYPE_CHECKING, TypeAlias

if TYPE_CHECKING:
    from pyproj import CRS

    from .catalog import Catalog
    from .source import Source

#: A file or folder path as the user gives it.
PathInput: TypeAlias = "str | os.PathLike[str]"
#: One path or several (files, folders, globs, ``.vpc`` files).
PathsInput: TypeAlias = "str | os.PathLike[str] | Iterable[str | os.PathLike[str]]"
#: A CRS as the user gives it: a pyproj CRS, an EPSG code, ``"EPSG:xxxx"``, WKT or a ``.prj``.
CRSInput: TypeAlias = "CRS | str | int | None"
#: Integer codes as the user gives them (one, several, or None for all).
IntsInput: TypeAlias = "int | Iterable[int] | None"
#: What the chunk functions read from: a catalog, or a source (a catalog with a selection).
Tiles: TypeAlias = "Catalog | Source"

__all__ = ["CRSInput", "IntsInput", "PathInput", "PathsInput", "Tiles"]
