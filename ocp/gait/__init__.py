"""Finger gaiting (docs/gait.md): a fingertip lifted off the still object, carried clear
and landed elsewhere while the others hold it (:mod:`ocp.gait.swing`, :mod:`ocp.gait.hold`,
:mod:`ocp.gait.step`), and a planner that turns a ball farther than rolling can by rolling
and re-placing fingertips in turn (:mod:`ocp.gait.planner`)."""
