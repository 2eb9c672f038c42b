"""Unit conversions at the edges (YAML, reports): the core speaks m, s, m/s and m/s² only."""

from __future__ import annotations

KMH = 1.0 / 3.6
"""One km/h in m/s."""

G = 9.81
"""Gravity, m/s² (Subset-026 A.3.1)."""


def kmh(value: float) -> float:
    """km/h → m/s."""
    return value / 3.6


def to_kmh(value: float) -> float:
    """m/s → km/h."""
    return value * 3.6
