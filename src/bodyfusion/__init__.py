"""bodyfusion: fusing body-worn pedestrian navigation systems under body distance constraints.

Packages: :mod:`bodyfusion.core` (layouts, plugin registry, the system interfaces, the fuser,
constraints, runs and their outputs: it knows no sensor), :mod:`bodyfusion.nav` (the navigation
toolbox the plugins share), :mod:`bodyfusion.io` (readers of IMU, truth, GNSS and phone-log
files), :mod:`bodyfusion.evaluation` (scoring and plots), :mod:`bodyfusion.plugins` (the built-in
sensor systems), :mod:`bodyfusion.sim` (simulation with truth), :mod:`bodyfusion.study`
(studies over many runs), :mod:`bodyfusion.testing` (the conformance kit for plugins).
"""

__version__ = "0.2.0"
