"""Shared fixtures: the synthetic cases (one source: spacefit/synthetic/, package data) and their references, rendered
once per test session."""

from __future__ import annotations

import functools

import spacefit as sf


@functools.cache
def reference(name: str, noise_percent: float = 0.0):
    """Case ``name``'s reference (and noise sigma), rendered once per session."""
    return sf.load_case(name).reference(noise_percent)
