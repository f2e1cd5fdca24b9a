"""Built-in sensor systems, registered through the ``fusion.plugins`` entry points like any third-party plugin."""
