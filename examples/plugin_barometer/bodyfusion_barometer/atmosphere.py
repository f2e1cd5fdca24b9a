"""Height from pressure in the troposphere of the International Standard Atmosphere.

Temperature falls linearly with height, T = T_ref − L (h − h_ref), so hydrostatic
balance gives

    p(h) = p_ref (1 − L (h − h_ref) / T_ref)^n,        n = g0 M / (R L) ≈ 5.2559,
    h(p) = h_ref + (T_ref / L) (1 − (p / p_ref)^(1/n)).

Pressures in Pa, heights in m (Up), temperatures in K. Near the ground one hPa is
about 8.3 m, one Pa about 8.3 cm.
"""

from __future__ import annotations

import numpy as np

LAPSE_RATE_K_PER_M = 0.0065
G0_MPS2 = 9.80665
MOLAR_MASS_KG_PER_MOL = 0.0289644
GAS_CONSTANT = 8.3144598
EXPONENT = G0_MPS2 * MOLAR_MASS_KG_PER_MOL / (GAS_CONSTANT * LAPSE_RATE_K_PER_M)
SEA_LEVEL_PA = 101325.0
SEA_LEVEL_K = 288.15


def pressure_at(h_m, p_ref_pa: float, t_ref_k: float = SEA_LEVEL_K, h_ref_m: float = 0.0):
    """Pressure (Pa) at height ``h_m`` given p_ref (Pa) and T_ref (K) at h_ref (m)."""
    return p_ref_pa * (1.0 - LAPSE_RATE_K_PER_M * (np.asarray(h_m) - h_ref_m) / t_ref_k) ** EXPONENT


def dpressure_dheight(h_m, p_ref_pa: float, t_ref_k: float = SEA_LEVEL_K, h_ref_m: float = 0.0):
    """∂p/∂h (Pa/m) of :func:`pressure_at`; negative."""
    base = 1.0 - LAPSE_RATE_K_PER_M * (np.asarray(h_m) - h_ref_m) / t_ref_k
    return -p_ref_pa * EXPONENT * LAPSE_RATE_K_PER_M / t_ref_k * base ** (EXPONENT - 1.0)


def height_at(p_pa, p_ref_pa: float, t_ref_k: float = SEA_LEVEL_K, h_ref_m: float = 0.0):
    """Height (m) at pressure ``p_pa``, the inverse of :func:`pressure_at`."""
    return h_ref_m + t_ref_k / LAPSE_RATE_K_PER_M * (1.0 - (np.asarray(p_pa) / p_ref_pa) ** (1.0 / EXPONENT))


def dheight_dpressure(p_pa, p_ref_pa: float, t_ref_k: float = SEA_LEVEL_K):
    """∂h/∂p (m/Pa) of :func:`height_at`; negative."""
    return -t_ref_k / (LAPSE_RATE_K_PER_M * EXPONENT * p_ref_pa) * (np.asarray(p_pa) / p_ref_pa) ** (1.0 / EXPONENT - 1.0)
