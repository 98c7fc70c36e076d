"""The public namespaces (what the API reference documents) hold no import leftovers."""

from __future__ import annotations

import importlib
import pkgutil

import lidarqa


def test_packages_do_not_expose_future_annotations() -> None:
    # `from __future__ import annotations` in a package's __init__ binds the name
    # `annotations`, which then shows up in dir(lidarqa) and in tab completion
    names = ["lidarqa"] + [
        f"lidarqa.{m.name}" for m in pkgutil.iter_modules(lidarqa.__path__) if m.ispkg
    ]
    assert len(names) > 5
    leaky = [n for n in names if "annotations" in dir(importlib.import_module(n))]
    assert not leaky, f"packages exposing 'annotations': {leaky}"
