"""Geometry of rolling contact: surfaces and their charts, Montana's contact kinematics (eq.
3), rotations, grasp angles and force closure, the palm/object contact's named functions.
"""
