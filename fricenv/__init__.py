"""fricenv: tire-road friction and force-sensor calibration workbench."""

from fricenv import envs as _envs  # noqa: F401  (registers the Gymnasium envs under "fricenv/")
