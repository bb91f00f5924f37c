"""Problem specification, data only: the object, the palm and the fingertips of a grasp,
the desired motion, the problems and their checks of input. The contact kinds' CasADi
models are :mod:`ocp.contacts`.
"""
