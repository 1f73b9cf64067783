"""The simulator's command lines (``scripts/<name>.py`` in a clone runs the same ``main``):
``play`` and ``record`` (bags), ``plot_run`` (a bag's plots), ``render_markers`` (the RViz
markers as images) and ``generate_urdf``."""
