"""Sphinx configuration for sb3-es (MyST Markdown, like Stable-Baselines3)."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

_version_file = ROOT / "sb3_es" / "version.txt"
release = _version_file.read_text().strip() if _version_file.exists() else "0.0.0"
version = release

project = "sb3-es"
author = "sb3-es developers"
copyright = "2026, sb3-es developers"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]

myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "show-inheritance": True}

nitpicky = False
# SB3's type annotations (aliases such as GymEnv, Schedule, th.device, ...) can resolve to
# several targets ("more than one target found for cross-reference"), which would break the
# `-W` build; they are not errors in our docs.
suppress_warnings = ["ref.python"]

html_theme = "alabaster"
html_static_path: list[str] = []
html_title = f"sb3-es {release}"
