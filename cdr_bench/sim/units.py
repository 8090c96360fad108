"""Unit conversions. Distances are km, speeds knots, times seconds, headings degrees clockwise
from north (090 = east); x points east and y north."""

KM_PER_NM = 1.852
"""Kilometres in one nautical mile."""

KM_PER_S_PER_KT = KM_PER_NM / 3600.0
"""km/s in one knot (1 kt = 1 NM/h)."""

KMH_PER_KT = KM_PER_NM
"""km/h in one knot."""


def kt_to_km_per_s(speed_kt: float) -> float:
    """Convert a speed in knots to km/s."""
    return speed_kt * KM_PER_S_PER_KT


def kmh_to_kt(speed_kmh: float) -> float:
    """Convert a speed in km/h to knots (800 km/h = 431.965 kt)."""
    return speed_kmh / KMH_PER_KT
