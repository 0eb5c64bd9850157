"""Unmodelled effects (the effect tables of docs/contracts.md) as switchable, parameterised extensions of the plants.

The same code builds the "real" stand-in of the gap tool and the augmented simulators its diagnosis fits.
Quarter car: :mod:`fricenv.effects.quarter_car` (simulator), :mod:`fricenv.effects.registry` (one entry per effect:
parameters, bounds, fit recipe, validation draw, plug-in hooks), :mod:`fricenv.effects.library` (the built-in effects'
specs and entries), :mod:`fricenv.effects.batch` (per-element parameters), :mod:`fricenv.effects.relaxation` (the
relaxation plant); planar payload: :mod:`fricenv.effects.payload`.
"""

from fricenv.effects.quarter_car import (
    EFFECT_PARAMS,
    EFFECTS,
    BrakeDelay,
    BrakeGain,
    BrakeLag,
    Drag,
    EffectSimulator,
    ModelBatch,
    MuChange,
    RadiusError,
    RelaxationLength,
    make_effect,
    simulate_with_effects,
)
from fricenv.effects.registry import Param, QuarterCarEffect, register, registered

__all__ = [
    "EFFECTS",
    "EFFECT_PARAMS",
    "BrakeDelay",
    "BrakeGain",
    "BrakeLag",
    "Drag",
    "EffectSimulator",
    "ModelBatch",
    "MuChange",
    "Param",
    "QuarterCarEffect",
    "RadiusError",
    "RelaxationLength",
    "make_effect",
    "register",
    "registered",
    "simulate_with_effects",
]
