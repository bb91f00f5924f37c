"""Solving: IPOPT's options and stop callback, compiled solvers, initial guesses and
strategies, the planning pipeline.
"""
