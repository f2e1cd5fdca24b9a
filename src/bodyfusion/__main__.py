"""``python -m bodyfusion``: the ``fusion`` command line."""

from bodyfusion.cli import main

main()
