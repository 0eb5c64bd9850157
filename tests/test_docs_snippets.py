"""Every Python block of the README and the docs runs as written, each on its own, from an empty directory.

A block is run in a fresh interpreter whose working directory is an empty temporary folder (so a block that reads
a file must write it first, and ``python -m`` commands must work from any directory), with the repository on
``PYTHONPATH``. A block preceded by ``<!-- slow -->`` (it trains a policy or starts Ray) runs in the slow set
(``pytest -m slow``); every other block runs in the default set.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```", re.DOTALL | re.MULTILINE)
SLOW_MARK = "<!-- slow -->"
FAST_TIMEOUT_S = 120
SLOW_TIMEOUT_S = 900


@dataclass(frozen=True)
class Snippet:
    """One fenced Python block: where it is, its code, and whether it is marked slow."""

    path: Path
    line: int
    code: str
    slow: bool

    @property
    def name(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def markdown_files() -> list[Path]:
    """README.md and every page under docs/."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def snippets(path: Path) -> list[Snippet]:
    """The fenced ``python`` blocks of one markdown file, in order."""
    text = path.read_text()
    found = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip().splitlines()
        slow = bool(before) and before[-1].strip() == SLOW_MARK
        found.append(Snippet(path, text.count("\n", 0, m.start()) + 1, m.group(1), slow))
    return found


ALL = [s for p in markdown_files() for s in snippets(p)]


def run(snippet: Snippet, cwd: Path, timeout: float) -> None:
    """Run one block in a fresh interpreter in ``cwd``; fail with its output if it does not exit 0."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg", "PYTHONHASHSEED": "0"}
    result = subprocess.run([sys.executable, "-c", snippet.code], cwd=cwd, env=env, capture_output=True,
                            text=True, timeout=timeout, check=False)
    assert result.returncode == 0, (f"{snippet.name} failed (exit {result.returncode}):\n{snippet.code}\n"
                                    f"--- stdout\n{result.stdout[-2000:]}\n--- stderr\n{result.stderr[-4000:]}")


def test_the_docs_hold_python_blocks_of_both_kinds():
    names = {s.path.name for s in ALL}
    assert "README.md" in names and len(ALL) >= 5
    assert any(s.slow for s in ALL) and any(not s.slow for s in ALL)


@pytest.mark.parametrize("snippet", [s for s in ALL if not s.slow], ids=lambda s: s.name)
def test_a_python_block_runs_as_written(snippet, tmp_path):
    run(snippet, tmp_path, FAST_TIMEOUT_S)


@pytest.mark.slow
@pytest.mark.parametrize("snippet", [s for s in ALL if s.slow], ids=lambda s: s.name)
def test_a_slow_python_block_runs_as_written(snippet, tmp_path):
    run(snippet, tmp_path, SLOW_TIMEOUT_S)
