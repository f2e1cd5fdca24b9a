"""The 1σ of an attitude's quaternion components and ZYX Euler angles from the covariance of
its error, to first order.

The attitude error is the small rotation δθ in the navigation frame (docs/conventions.md):
C_nb,true = (I + [δθ×]) C_nb, that is q_true = [1, δθ/2] ⊗ q_nb. Then

    δq = G δθ,   G = ½ [ −q_vᵀ ; q_w I − [q_v×] ]                      (4 × 3),
    δθ = M δe,   M = [ e_U | R_z(ψ) e_N | R_z(ψ) R_y(θ) e_E ]           (3 × 3),

for the ZYX Euler angles e = (ψ yaw, θ pitch, φ roll) of C_nb = R_z(ψ) R_y(θ) R_x(φ) in ENU
(the angular velocity of a ZYX sequence), so Σ_q = G Σ Gᵀ and Σ_e = M⁻¹ Σ M⁻ᵀ. At pitch
±90° (gimbal lock) M is singular: the Euler σ there is NaN.
"""

from __future__ import annotations

import numpy as np

PACKED_ORDER = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
"""Entries of a packed (N, 6) symmetric 3 × 3 covariance: EE, NN, UU, EN, EU, NU."""


def unpack_covariance(packed: np.ndarray) -> np.ndarray:
    """(N, 3, 3) symmetric matrices from their (N, 6) entries in :data:`PACKED_ORDER`."""
    packed = np.asarray(packed, dtype=float)
    out = np.empty((len(packed), 3, 3))
    for c, (a, b) in enumerate(PACKED_ORDER):
        out[:, a, b] = out[:, b, a] = packed[:, c]
    return out


def quaternion_sd(q_nb: np.ndarray, attitude_cov: np.ndarray) -> np.ndarray:
    """(N, 4) 1σ of q_nb's components ``[w, x, y, z]`` (N, 4) given the attitude error
    covariance (N, 3, 3) rad² (module docstring: G Σ Gᵀ)."""
    q = np.asarray(q_nb, dtype=float)
    w, v = q[:, 0], q[:, 1:4]
    G = np.empty((len(q), 4, 3))
    G[:, 0, :] = -v
    G[:, 1:, :] = w[:, None, None] * np.eye(3)
    G[:, 1, 1] += v[:, 2]  # − [v×]
    G[:, 1, 2] -= v[:, 1]
    G[:, 2, 0] -= v[:, 2]
    G[:, 2, 2] += v[:, 0]
    G[:, 3, 0] += v[:, 1]
    G[:, 3, 1] -= v[:, 0]
    G *= 0.5
    var = np.einsum("nij,njk,nik->ni", G, attitude_cov, G)
    return np.sqrt(np.maximum(var, 0.0))


def euler_sd_deg(q_nb: np.ndarray, attitude_cov: np.ndarray) -> np.ndarray:
    """(N, 3) 1σ (deg) of the ZYX Euler angles roll, pitch, yaw of q_nb (N, 4) in ENU given
    the attitude error covariance (N, 3, 3) rad² (module docstring: M⁻¹ Σ M⁻ᵀ); NaN where
    the pitch is ±90°."""
    q = np.asarray(q_nb, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    M = np.zeros((len(q), 3, 3))
    M[:, 2, 0] = 1.0
    M[:, 0, 1], M[:, 1, 1] = -np.sin(yaw), np.cos(yaw)
    M[:, 0, 2], M[:, 1, 2], M[:, 2, 2] = np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), -np.sin(pitch)
    out = np.full((len(q), 3), np.nan)
    ok = np.abs(np.cos(pitch)) > 1e-9
    if ok.any():
        Minv = np.linalg.inv(M[ok])
        var = np.einsum("nij,njk,nik->ni", Minv, attitude_cov[ok], Minv)  # yaw, pitch, roll
        out[ok] = np.degrees(np.sqrt(np.maximum(var[:, ::-1], 0.0)))
    return out
