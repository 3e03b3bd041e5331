"""Unit conversions for the edges: feet, knots and inches of mercury in, SI inside."""

FT_TO_M = 0.3048
KT_TO_MPS = 1852.0 / 3600.0
KMH_TO_MPS = 1000.0 / 3600.0
STATUTE_MILE_TO_M = 1609.344
INHG_TO_HPA = 33.863886666667


def ft_to_m(ft: float) -> float:
    return ft * FT_TO_M


def m_to_ft(m: float) -> float:
    return m / FT_TO_M


def kt_to_mps(kt: float) -> float:
    return kt * KT_TO_MPS


def mps_to_kt(mps: float) -> float:
    return mps / KT_TO_MPS


def inhg_to_hpa(inhg: float) -> float:
    return inhg * INHG_TO_HPA
