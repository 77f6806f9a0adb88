"""The Sphinx docs build without warnings (same flags as `make docs`)."""

from pathlib import Path

import pytest

DOCS_DIR = Path(__file__).resolve().parent.parent / "docs"


def test_docs_build(tmp_path: Path) -> None:
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    from sphinx.cmd.build import build_main

    out_dir = tmp_path / "html"
    doctree_dir = tmp_path / "doctrees"
    args = ["-W", "--keep-going", "-b", "html", "-q", "-d", str(doctree_dir), str(DOCS_DIR), str(out_dir)]
    assert build_main(args) == 0
    assert (out_dir / "index.html").exists()
