"""Certification: the certificate type (checks with name, value, tolerance and kind; the
tolerance policies) and the independent certification of a plan.
"""
