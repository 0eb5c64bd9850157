"""A step of Braking-v0 reads top down: ``env.unwrapped.step`` enters at most five fricenv files (sys.settrace)."""

from __future__ import annotations

import pathlib
import sys

import gymnasium as gym
import numpy as np

import fricenv

PACKAGE = str(pathlib.Path(fricenv.__file__).resolve().parent)
MAX_FILES = 5


def _files_entered(step) -> set[str]:
    """The fricenv source files with a Python call during ``step()``."""
    seen: set[str] = set()

    def trace(frame, event, arg):
        if event == "call" and frame.f_code.co_filename.startswith(PACKAGE):
            seen.add(pathlib.Path(frame.f_code.co_filename).name)

    sys.settrace(trace)
    try:
        step()
    finally:
        sys.settrace(None)
    return seen


def test_a_braking_step_enters_at_most_five_fricenv_files():
    """Every step of a stop over a friction change (the change, the stop and the episode's end included)."""
    env = gym.make("fricenv/Braking-v0", road="dry->ice", change_distance=10.0, v0=15.0).unwrapped
    env.reset(seed=0)
    action = np.array([0.2], dtype=np.float32)
    out = {}
    per_step = []
    done = False
    while not done:
        files = _files_entered(lambda: out.update(r=env.step(action)))
        per_step.append(files)
        done = out["r"][2] or out["r"][3]
    assert env.sim.switched[0] and out["r"][2]  # the change and the stop happened inside the traced steps
    widest = max(per_step, key=len)
    assert len(widest) <= MAX_FILES, sorted(widest)
    assert {"braking.py", "braking_sim.py"} <= widest
