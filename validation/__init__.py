"""Measurements of the library against its targets, each runnable as ``python -m validation.NAME`` from the repo root.

The library (fricenv, estimators, agents) never imports this package (an import-linter contract in pyproject.toml).
"""
