"""wptrack benchmark suites (run them with ``wptrack bench``). Each suite registers itself in ``SUITES``; a new
tracker plugs in with a module defining a suite class (``name``, ``default_grid(device)``, ``run_case(...)``) and
one line here."""

from __future__ import annotations

from .colour import ColourSuite
from .endtoend import EndToEndSuite
from .masks import MasksSuite
from .templates import TemplateSuite

SUITES = {ColourSuite.name: ColourSuite, EndToEndSuite.name: EndToEndSuite, TemplateSuite.name: TemplateSuite}
SUITES[MasksSuite.name] = MasksSuite
