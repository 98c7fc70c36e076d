"""The analyses an assessment can run: one module per analysis kind.

Each module (``info``, ``ground``, ``edges``, ``lines``, ``checkpoints``,
``heights``) holds the section function ``run(ctx, item) -> SectionResult``
of one kind and registers it, with its config keys, pass/fail targets and
default title, through :func:`~lidarqa.report._registry.register`. The
function takes the run context (loaded inputs, output folder, progress) and
the validated config item, calls the library, and returns the ``results``
dict for ``report.json``, the figures and tables for the HTML page and the
output files it wrote. :func:`~lidarqa.report._registry.library_params` tells
the config validator which library keyword arguments an analysis accepts (by
introspecting the library function), so the config uses the same names as the
API and the CLI.

Adding an analysis: write ``report/analyses/<kind>.py`` (see ``info.py`` for
the smallest one). Every module of this package is imported here, and the
``order`` given to ``register`` places it among the report's sections.
"""

from __future__ import annotations

import importlib
import pkgutil

#: the analysis modules of this package (importing one registers it); modules
#: whose name starts with "_" are helpers and are not imported here
BUILTIN = tuple(
    sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
)
for _name in BUILTIN:
    importlib.import_module(f"{__name__}.{_name}")

__all__ = ["BUILTIN"]
