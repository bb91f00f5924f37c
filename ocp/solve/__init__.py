"""Solving: IPOPT's options and stop callback, compiled solvers, initial guesses (each
contact kind's: :mod:`.contact_guesses`) and strategies, the planning pipeline, and the
independent certification of a plan (:mod:`.certify`, each contact kind's checks:
:mod:`.contact_checks`).
"""
