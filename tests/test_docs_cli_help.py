"""The command line's help texts say what the code does, and point only to documents that exist.

Every verb's ``--help`` (its module docstring and options) is rendered from the parser ``fricenv`` builds.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from fricenv.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]


def help_texts() -> dict[str, str]:
    """``{"gap diagnose": help text, ...}`` for every verb and sub-verb."""
    texts: dict[str, str] = {}

    def walk(parser: argparse.ArgumentParser, name: str) -> None:
        texts[name] = parser.format_help()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub, sub_parser in action.choices.items():
                    walk(sub_parser, f"{name} {sub}".strip())

    walk(build_parser(), "")
    return texts


HELP = help_texts()


def test_every_verb_has_help():
    assert {"demo", "train", "tune", "gap diagnose", "gap simulate"} <= set(HELP)


@pytest.mark.parametrize("verb", sorted(HELP), ids=lambda v: v or "fricenv")
def test_help_points_to_documents_that_exist(verb):
    text = HELP[verb]
    assert "DESIGN.md" not in text
    assert "python -m tests." not in text  # works only from the repository root
    for doc in re.findall(r"docs/[\w/-]+\.md", text):
        assert (ROOT / doc).is_file(), f"fricenv {verb} --help names {doc}, which does not exist"


def test_tune_help_states_the_score_the_code_computes():
    from agents.tuning import LOCK_PENALTY, WORST_WEIGHT

    text = " ".join(HELP["tune"].split())
    assert f"+ {WORST_WEIGHT} x (worst scenario's mean ratio - 1)" in text
    assert f"+ {LOCK_PENALTY} x share of locked episodes" in text
