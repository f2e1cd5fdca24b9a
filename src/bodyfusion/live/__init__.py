"""Live fusion: a layout run as its recordings arrive (:mod:`bodyfusion.live.engine`), fed by a
replay or a line stream (:mod:`bodyfusion.live.sources`), its states written as they are made
(:mod:`bodyfusion.live.sinks`). ``fusion live`` on the command line."""
