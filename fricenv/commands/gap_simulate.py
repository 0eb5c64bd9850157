"""Write a quarter-car log from the real stand-in with chosen unmodelled effects (docs/contracts.md log format).

Example: fricenv gap simulate --effect brake_lag --param tau=0.04 --road wet --driver abs --seed 3 --out log.csv

Several effects at once: repeat --effect and give each parameter as --param NAME=VALUE (parameter names are unique
across the library), or qualify it as --param EFFECT.NAME=VALUE. The logged torque is the commanded torque, before
any actuator effect; the log starts with a short free-rolling stretch; the wheel speed has noise variance
0.2 (rad/s)^2, v and a_x (unless --no-v / --no-ax) small noise.

--plant payload writes a payload log (t, M, f_x, f_y raw readings, theta, X, Y vision) from
fricenv.effects.payload.simulate_payload_with_effects, e.g.
fricenv gap simulate --plant payload --effect vision_delay --param delay=0.03 --duration 10 --out log.csv
(calibration_error: --param S=s11,s12,...,s33, row-major).
"""

from __future__ import annotations

import argparse
import math

from fricenv.errors import InvalidInputError, user_input

# --out is the log file (not a directory); checked with the other paths by fricenv.cli before the simulation.
PATH_OPTIONS = {"out": "output file"}
MAX_V0 = 100.0  # [m/s], the log reader's plausibility limit of v


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fricenv gap simulate``."""
    parser.add_argument("--plant", default="quarter-car", help="quarter-car or payload (default %(default)s)")
    parser.add_argument("--dt", type=float, default=None, help="payload only: sample time [s] (default 0.001)")
    parser.add_argument("--wrench", default="paper",
                        help="payload only: paper (eq. 13) or random (eq. 13 with seeded random frequencies and "
                             "phases; default %(default)s)")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="effect to switch on (repeatable); none for the nominal plant")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="effect parameter, SI units (repeatable)")
    parser.add_argument("--road", default="dry", help="road preset (dry, wet, snow, ice; default %(default)s)")
    parser.add_argument("--driver", default="abs", help="abs or open-loop (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default %(default)s)")
    parser.add_argument("--duration", type=float, default=5.0, help="longest log [s] (default %(default)s)")
    parser.add_argument("--v0", type=float, default=None, help="initial speed [m/s] (default: random 20-32)")
    parser.add_argument("--no-v", action="store_true", help="do not write the v column")
    parser.add_argument("--no-ax", action="store_true", help="do not write the a_x column")
    parser.add_argument("--out", required=True, help="output CSV")
    parser.add_argument("--json", metavar="PATH", help="write the truth (effects, road, driver) as JSON")


def parse_effects(names: list[str], params: list[str]) -> list:
    """Effect specs from --effect names and --param NAME=VALUE / EFFECT.NAME=VALUE strings."""
    from fricenv.effects.quarter_car import EFFECT_PARAMS, make_effect

    names = [n for n in names if n != "none"]
    for n in names:
        if n not in EFFECT_PARAMS:
            raise InvalidInputError(f"unknown effect {n!r}; valid effects: {', '.join(EFFECT_PARAMS)}")
    values: dict[str, dict[str, float]] = {n: {} for n in names}
    for item in params:
        if "=" not in item:
            raise InvalidInputError(f"--param {item!r}: expected NAME=VALUE")
        key, value = item.split("=", 1)
        try:
            val = float(value)
        except ValueError:
            raise InvalidInputError(f"--param {item!r}: {value!r} is not a number") from None
        if "." in key:
            eff, pname = key.split(".", 1)
            if eff not in values:
                raise InvalidInputError(f"--param {item!r}: effect {eff!r} is not among --effect {', '.join(names)}")
            values[eff][pname] = val
            continue
        owners = [n for n in names if key in EFFECT_PARAMS[n]]
        if not owners:
            valid = ", ".join(f"{p} ({n})" for n in names for p in EFFECT_PARAMS[n]) or "none (no --effect given)"
            raise InvalidInputError(f"--param {item!r}: unknown parameter {key!r}; valid parameters: {valid}")
        values[owners[0]][key] = val
    with user_input("--param"):
        return [make_effect(n, **values[n]) for n in names]


def parse_payload_effects(names: list[str], params: list[str]) -> list:
    """Payload effect specs from --effect names and --param NAME=VALUE strings (``S`` takes 9 comma-separated
    values, row-major)."""
    from fricenv.effects.payload import PAYLOAD_EFFECT_PARAMS, make_payload_effect

    names = [n for n in names if n != "none"]
    for n in names:
        if n not in PAYLOAD_EFFECT_PARAMS:
            raise InvalidInputError(f"unknown payload effect {n!r}; "
                                    f"valid effects: {', '.join(PAYLOAD_EFFECT_PARAMS)}")
    values: dict[str, dict] = {n: {} for n in names}
    for item in params:
        if "=" not in item:
            raise InvalidInputError(f"--param {item!r}: expected NAME=VALUE")
        key, value = item.split("=", 1)
        if "." in key:
            eff, key = key.split(".", 1)
            owners = [eff] if eff in values else []
        else:
            owners = [n for n in names if key in PAYLOAD_EFFECT_PARAMS[n]]
        if not owners or key not in PAYLOAD_EFFECT_PARAMS[owners[0]]:
            valid = ", ".join(f"{p} ({n})" for n in names for p in PAYLOAD_EFFECT_PARAMS[n]) or "none (no --effect)"
            raise InvalidInputError(f"--param {item!r}: unknown parameter {key!r}; valid parameters: {valid}")
        try:
            nums = [float(v) for v in value.split(",")]
        except ValueError:
            raise InvalidInputError(f"--param {item!r}: {value!r} is not a number "
                                    "(S: 9 comma-separated numbers)") from None
        if key == "S":
            if len(nums) != 9:
                raise InvalidInputError(f"--param {item!r}: S needs 9 comma-separated values (row-major), "
                                        f"got {len(nums)}")
            values[owners[0]][key] = [nums[0:3], nums[3:6], nums[6:9]]
        elif len(nums) != 1:
            raise InvalidInputError(f"--param {item!r}: expected one number")
        else:
            values[owners[0]][key] = nums[0]
    with user_input("--param"):
        return [make_payload_effect(n, **values[n]) for n in names]


def payload_wrench(kind: str, rng):
    """The true wrench ``w(t)`` of a simulated payload log (see :func:`fricenv.plants.payload.multisine_wrench`)."""
    from fricenv.plants.payload import multisine_wrench

    return multisine_wrench(kind, rng)


def _names(effect) -> list[str]:
    from dataclasses import fields

    return [f.name for f in fields(effect)]


def run_payload(args: argparse.Namespace) -> int:
    """``--plant payload``: simulate the payload stand-in with effects and write its log."""
    import os

    from fricenv.effects.payload import simulate_payload_with_effects
    from fricenv.logs import LogFormatError, read_log, write_log
    from fricenv.utils import as_generator, write_json

    effects = parse_payload_effects(args.effect, args.param)
    dt = 1e-3 if args.dt is None else float(args.dt)
    if not (math.isfinite(dt) and 0 < dt < args.duration):
        raise InvalidInputError(f"--dt must be > 0 and below --duration, got {args.dt}")
    rng = as_generator(args.seed)
    with user_input("--wrench"):
        wrench = payload_wrench(args.wrench, rng)
    log, _ = simulate_payload_with_effects(effects, args.duration, dt, wrench=wrench, rng=rng)
    desc = "; ".join(f"{e.name}({', '.join(f'{k}={getattr(e, k)}' for k in _names(e))})"
                     for e in effects) or "no effect"
    write_log(args.out, log, comments=(f"fricenv gap simulate --plant payload: wrench={args.wrench}, seed={args.seed}",
                                       f"effects: {desc}"))
    try:
        read_log(args.out, "payload")
    except LogFormatError as exc:  # the free payload drifts: a long log leaves the reader's plausible range
        os.unlink(args.out)
        raise InvalidInputError(f"the simulated log is not a valid payload log ({exc}); "
                                "use a shorter --duration") from None
    print(f"wrote {args.out}: {len(log)} samples ({len(log) * dt:.2f} s), payload, wrench {args.wrench}, {desc}")
    if args.json:
        write_json(args.json, {"log": args.out, "plant": "payload", "samples": len(log), "dt": dt,
                               "seed": args.seed, "wrench": args.wrench,
                               "effects": [{"effect": e.name, "params": {k: getattr(e, k)
                                                                         for k in _names(e)}}
                                           for e in effects]})
    return 0


def check_options(args: argparse.Namespace) -> None:
    """Reject option values the simulation cannot use, before it starts (both plants)."""

    if not (math.isfinite(args.duration) and args.duration > 0):
        raise InvalidInputError(f"--duration must be a number > 0 [s], got {args.duration}")


def _check_quarter_car(args: argparse.Namespace) -> None:
    """The quarter car's own options: a known driver, a plausible initial speed, no payload option."""
    from fricenv.gap.quarter_car.simulate import DRIVERS

    if args.driver not in DRIVERS:
        raise InvalidInputError(f"unknown driver {args.driver!r}; valid drivers: {', '.join(DRIVERS)}")
    if args.v0 is not None and not (math.isfinite(args.v0) and 0 < args.v0 <= MAX_V0):
        raise InvalidInputError(f"--v0 must be a speed in (0, {MAX_V0:g}] m/s, got {args.v0}")


def run(args: argparse.Namespace) -> int:
    """Simulate and write the log of the plant ``--plant``."""
    runner = RUNNERS.get(args.plant)
    if runner is None:
        raise InvalidInputError(f"unknown plant {args.plant!r}; valid plants: {', '.join(RUNNERS)}")
    check_options(args)
    return runner(args)


def run_quarter_car(args: argparse.Namespace) -> int:
    """``--plant quarter-car``: the real stand-in with the chosen effects and driver."""
    _check_quarter_car(args)
    if args.dt is not None or args.wrench != "paper":
        raise InvalidInputError("--dt and --wrench apply to --plant payload only")
    from fricenv.effects.quarter_car import effect_params
    from fricenv.gap.quarter_car.simulate import write_simulated_log
    from fricenv.plants.tire import get_road
    from fricenv.utils import write_json

    effects = parse_effects(args.effect, args.param)
    road = get_road(args.road)
    kwargs = {} if args.v0 is None else {"v0": args.v0}
    truth = write_simulated_log(args.out, effects, road, args.driver, args.seed, args.duration,
                                write_v=not args.no_v, write_ax=not args.no_ax, **kwargs)
    n = len(truth["v"])
    desc = ", ".join(f"{e.name}({', '.join(f'{k}={v:g}' for k, v in effect_params(e).items())})"
                     for e in effects) or "no effect"
    print(f"wrote {args.out}: {n} samples ({n * 0.01:.2f} s), road {road.name}, driver {args.driver}, {desc}")
    if args.json:
        write_json(args.json, {"log": args.out, "samples": n, "road": args.road, "driver": args.driver,
                               "seed": args.seed, "v0": truth["v0"],
                               "effects": [{"effect": e.name, "params": effect_params(e)} for e in effects]})
    return 0


RUNNERS = {"quarter-car": run_quarter_car, "payload": run_payload}
