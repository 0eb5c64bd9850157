"""The layer contracts of pyproject.toml ([tool.importlinter]) hold, and the check fails on a wrong-way import."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: pytest's own dependency
    import tomli as tomllib

pytest.importorskip("importlinter", reason="import-linter is in the dev extra")

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fricenv", "estimators", "agents")
CLI = ("fricenv.cli", "fricenv.commands", "agents.commands", "fricenv.__main__")
# The linter in a fresh interpreter, run from the project root it is given (cwd), without its cache.
LINT = ("import sys; from importlinter.cli import lint_imports; "
        "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")


def _lint(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", LINT], check=False, cwd=root, capture_output=True, text=True,
                          timeout=300)


def _contracts() -> list[dict]:
    with open(ROOT / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)["tool"]["importlinter"]["contracts"]


def test_layer_contracts_hold():
    res = _lint(ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert f"{len(_contracts())} kept, 0 broken" in res.stdout


def _modules() -> list[str]:
    names = []
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


def test_cli_contract_covers_every_library_module():
    """A new library module must be added to the sources of the "no library module imports the CLI" contract."""
    (cli,) = [c for c in _contracts() if c["id"] == "cli-on-top"]
    sources = cli["source_modules"]
    library = [m for m in _modules() if m not in PACKAGES and not any(m == c or m.startswith(c + ".") for c in CLI)]
    missing = [m for m in library if not any(m == s or m.startswith(s + ".") for s in sources)]
    assert len(library) > 40  # the walk found the project
    assert missing == [], f"add to cli-on-top's source_modules in pyproject.toml: {missing}"


@pytest.mark.parametrize("module, line, contract, chain", [
    ("fricenv/plants/tire.py", "import agents.pipeline", "core-layers", "fricenv.plants.tire -> agents.pipeline"),
    ("fricenv/plants/payload.py", "from fricenv.logs import PayloadLog", "core-layers",
     "fricenv.plants.payload -> fricenv.logs"),
    ("fricenv/effects/quarter_car.py", "import fricenv.gap.quarter_car.simulate", "gap-layers",
     "fricenv.effects.quarter_car -> fricenv.gap.quarter_car.simulate"),
    ("fricenv/envs/braking.py", "import fricenv.cli", "cli-on-top", "fricenv.envs.braking -> fricenv.cli"),
])
def test_wrong_way_import_breaks_a_contract(tmp_path, module, line, contract, chain):
    """The three packages copied to tmp_path with one wrong-way import added: the linter reports that contract."""
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    target = tmp_path / module
    target.write_text(target.read_text() + f"\n{line}  # wrong way\n")
    res = _lint(tmp_path)
    assert res.returncode == 1, res.stdout + res.stderr
    out = " ".join(res.stdout.split())  # the report wraps long names
    names = {c["id"]: c["name"] for c in _contracts()}  # (an indirect chain may break another contract too)
    assert f"{names[contract]} BROKEN" in out, res.stdout
    assert chain in out, res.stdout


# Test folders that must stay apart from the RL side (estimators and plants are tested on their own), and what
# they may not import, directly or through tests.* helpers.
ISOLATED_TESTS = {"estimators": ("agents", "fricenv.envs", "stable_baselines3", "gymnasium"),
                  "plants": ("agents", "fricenv.envs", "stable_baselines3", "gymnasium")}


def _imports(path: Path) -> set[str]:
    import ast

    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _banned(names: set[str], banned: tuple[str, ...]) -> list[str]:
    return sorted(n for n in names if any(n == b or n.startswith(b + ".") for b in banned))


@pytest.mark.parametrize("folder", sorted(ISOLATED_TESTS))
def test_estimator_and_plant_tests_never_touch_the_rl_side(folder):
    files = sorted((ROOT / "tests" / folder).glob("*.py"))
    assert len(files) >= 3  # the folder exists and holds its tests
    offending = {f.name: _banned(_imports(f), ISOLATED_TESTS[folder]) for f in files}
    assert {k: v for k, v in offending.items() if v} == {}


def test_the_isolation_check_sees_a_wrong_import(tmp_path):
    bad = tmp_path / "test_bad.py"
    bad.write_text("import numpy\nfrom fricenv.envs.braking import BrakingEnv\nimport agents.training\n")
    assert _banned(_imports(bad), ISOLATED_TESTS["estimators"]) == ["agents.training", "fricenv.envs.braking"]
