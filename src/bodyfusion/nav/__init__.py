"""Navigation toolbox shared by the plugins: attitude conventions, Earth model, strapdown
mechanisation, the 15-state error model, zero-velocity updates and detectors, initial
alignment, measurement gating. Pure functions and compiled kernels; no layout, no files."""
