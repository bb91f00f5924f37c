"""Controllers that track a certified plan from measured states (docs/control.md):
:class:`~ocp.control.window.WindowController`, a short window re-solved at a fixed rate."""

from ocp.control.window import ControllerOptions, Tick, WindowController

__all__ = ["ControllerOptions", "Tick", "WindowController"]
