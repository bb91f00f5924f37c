"""Problem specification: the object, its contacts (each a model object owning its states,
rolling equations, path rows and certificate laws), the desired motion, the problems.
"""
