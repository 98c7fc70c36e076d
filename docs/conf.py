"""Sphinx configuration of the lidarqa documentation.

Build: ``sphinx-build -W -b html docs docs/_build/html`` (the test suite does this,
with warnings as errors, in tests/docs/test_docs_build.py, against the installed package).
"""

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
if not os.environ.get("LIDARQA_DOCS_INSTALLED"):
    # document this checkout, not an installed copy; the test suite sets LIDARQA_DOCS_INSTALLED
    # to document the package it tests (installed, so nothing is written into src/)
    sys.path.insert(0, str(HERE.parent / "src"))

import lidarqa  # noqa: E402

project = "lidarqa"
author = "lidarqa developers"
copyright = "lidarqa developers, BSD-3-Clause"  # noqa: A001
release = lidarqa.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "lidarqa_docs",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_ext", "README.md"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

# numpydoc-style docstrings
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_param = False  # parameter types as text, not cross-references
napoleon_use_ivar = True
autodoc_typehints = "description"
autodoc_member_order = "bysource"

html_theme = "alabaster"
html_title = f"lidarqa {release}"
html_static_path: list[str] = []
html_theme_options = {
    "description": "How accurate is this LiDAR point cloud?",
    "page_width": "1100px",
}
