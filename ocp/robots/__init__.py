"""Robots: fingers from URDF through Pinocchio, the built-in hands, their model files.
"""
