"""Write data/stairs_pressure.csv: 60 s at 25 Hz of a walker who climbs one storey
(3 m) and comes back down, as a phone barometer would record it.

Truth heights follow rest (0–10 s), climb at 0.2 m/s (10–25 s), level (25–40 s),
descend (40–55 s), rest. Pressure: the standard atmosphere at 250 m above sea level,
a weather drift of +0.01 Pa/s, white noise σ = 2.5 Pa, rounded to 0.01 Pa. The
``up_m`` column is the truth (ignored by the plugin). Seeded: the file is reproducible.
"""

from pathlib import Path

import numpy as np

from bodyfusion_barometer.atmosphere import SEA_LEVEL_K, SEA_LEVEL_PA, pressure_at

RATE_HZ, DURATION_S, SITE_M = 25.0, 60.0, 250.0


def truth_height(t: np.ndarray) -> np.ndarray:
    return np.interp(t, [0, 10, 25, 40, 55, 60], [0, 0, 3, 3, 0, 0])


def main(out: Path = Path(__file__).with_name("data") / "stairs_pressure.csv") -> None:
    rng = np.random.default_rng(2024)
    t = np.arange(int(DURATION_S * RATE_HZ) + 1) / RATE_HZ
    up = truth_height(t)
    p = pressure_at(SITE_M + up, SEA_LEVEL_PA, SEA_LEVEL_K) + 0.01 * t + rng.normal(0, 2.5, t.size)
    out.parent.mkdir(exist_ok=True)
    rows = "\n".join(f"{a:.2f},{b:.2f},{c:.4f}" for a, b, c in zip(t, p, up))
    out.write_text("t_s,pressure_pa,up_m\n" + rows + "\n")
    print(f"wrote {out} ({t.size} rows)")


if __name__ == "__main__":
    main()
