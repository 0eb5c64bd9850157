"""The ``fricenv`` console script: one verb per module.

Each verb lives in its own module exposing ``add_arguments(parser)`` and ``run(args) -> int``; this file only maps
verb names to modules, so adding a verb never touches another verb's code. Modules are imported when the parser is
built, so they keep heavy imports (torch, casadi, SB3) inside ``run``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# (verb, sub-verb or None) -> module. Order is the order shown by --help.
VERBS: dict[tuple[str, str | None], str] = {
    ("demo", None): "fricenv.commands.demo",
    ("bench", None): "fricenv.commands.bench",
    ("paper", "mhe"): "fricenv.commands.paper_mhe",
    ("paper", "ekf-rls"): "fricenv.commands.paper_ekf_rls",
    ("paper", "fms"): "fricenv.commands.paper_fms",
    ("excitation", None): "agents.commands.excitation",
    ("train", None): "agents.commands.train",
    ("evaluate", None): "agents.commands.evaluate",
    ("compare", None): "agents.commands.compare",
    ("gap", "simulate"): "fricenv.commands.gap_simulate",
    ("gap", "diagnose"): "fricenv.commands.gap_diagnose",
    ("gap", "policy"): "agents.commands.gap_policy",
    ("gap", "validate"): "fricenv.commands.gap_validate",
}


def _load(module_name: str):
    """The verb module, or None if that verb is not part of this installation yet."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name == module_name:
            return None
        raise


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, one sub-parser per available verb."""
    parser = argparse.ArgumentParser(
        prog="fricenv", description="Tire-road friction and force-sensor calibration workbench."
    )
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    groups: dict[str, argparse._SubParsersAction] = {}
    for (verb, sub), module_name in VERBS.items():
        module = _load(module_name)
        if module is None:
            continue
        doc = (module.__doc__ or "").strip().splitlines()
        help_text = doc[0] if doc else None
        if sub is None:
            p = verbs.add_parser(verb, help=help_text, description=module.__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
        else:
            if verb not in groups:
                group_parser = verbs.add_parser(verb, help=f"{verb} sub-commands")
                groups[verb] = group_parser.add_subparsers(dest="sub", metavar="SUB", required=True)
            p = groups[verb].add_parser(sub, help=help_text, description=module.__doc__,
                                        formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``fricenv`` console script."""
    args = build_parser().parse_args(argv)
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
