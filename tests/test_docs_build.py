"""The documentation site builds strictly: a broken link, anchor, page or API reference fails the build.

``make docs`` runs the same build. The API reference is generated from the docstrings by mkdocstrings (static
analysis: nothing is imported). Skipped, with the reason, when MkDocs is not installed (``pip install -e '.[dev]'``).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("mkdocs", reason="MkDocs is not installed: pip install -e '.[dev]' installs the docs tools")
pytest.importorskip("material", reason="mkdocs-material is not installed: pip install -e '.[dev]'")
pytest.importorskip("mkdocstrings_handlers.python", reason="mkdocstrings[python] is not installed: pip install -e '.[dev]'")


def build(config: Path, site: Path) -> subprocess.CompletedProcess:
    """``mkdocs build --strict`` of ``config`` into ``site``."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
                           "--site-dir", str(site)], cwd=config.parent, env=env, capture_output=True, text=True,
                          timeout=300, check=False)


def test_the_docs_site_builds_strictly(tmp_path):
    result = build(ROOT / "mkdocs.yml", tmp_path / "site")
    problems = [line for line in result.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert result.returncode == 0, "mkdocs build --strict failed:\n" + "\n".join(problems or [result.stderr[-3000:]])
    for page in ("index.html", "contracts/index.html", "api/gap/index.html", "guides/gap/index.html"):
        assert (tmp_path / "site" / page).is_file(), page
    # the API reference is generated from the docstrings: the package page documents its submodules
    assert "fricenv.gap." in (tmp_path / "site" / "api" / "gap" / "index.html").read_text()
    assert not readme_link_problems(tmp_path / "site")


def readme_link_problems(site: Path) -> list[str]:
    """README.md lives outside the site: each of its relative links must name a file that exists, and a link into a
    docs page with an anchor must name a heading the built page has."""
    problems = []
    for target in re.findall(r"\]\(([^)\s]+)\)", (ROOT / "README.md").read_text()):
        if re.match(r"[a-z]+://", target):
            continue
        path, _, anchor = target.partition("#")
        if not (ROOT / path).exists():
            problems.append(f"README links to {path}, which does not exist")
        elif anchor and path.startswith("docs/") and path.endswith(".md"):
            page = path[len("docs/"):-len(".md")]
            html = site / ("index.html" if page == "index" else f"{page}/index.html")
            if f'id="{anchor}"' not in html.read_text():
                problems.append(f"README links to {target}: no such heading")
    return problems


def test_a_broken_link_fails_the_strict_build(tmp_path):
    """The project's configuration with one page that links to a page that does not exist."""
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text("# Home\n\nSee [the missing page](missing.md) and [an anchor](#nowhere).\n")
    config = tmp_path / "mkdocs.yml"
    text = (ROOT / "mkdocs.yml").read_text()
    config.write_text(text.split("\nnav:")[0] + "\nnav:\n  - Home: index.md\n")
    result = build(config, tmp_path / "site")
    assert result.returncode != 0
    assert "missing.md" in result.stderr
