"""Robot models shipped with dexroll (URDF files, read with importlib.resources)."""
