"""Unmodelled effects (DESIGN.md effect tables) as switchable, parameterised extensions of the plants.

The same code builds the "real" stand-in of the gap tool and the augmented simulators its diagnosis fits.
Quarter car: :mod:`fricenv.effects.quarter_car`; planar payload: :mod:`fricenv.effects.payload`.
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
    "RadiusError",
    "RelaxationLength",
    "make_effect",
    "simulate_with_effects",
]
