"""Built-in sensor systems, registered through the ``bodyfusion.core.registry`` entry points like any third-party plugin."""
