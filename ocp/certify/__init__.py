"""The certificate's types (:mod:`.certificate`: checks with name, value, tolerance and
kind; the tolerance policies): a leaf every layer may use. The certification of a plan
reads the transcription's trajectory and lives in the solve layer
(:mod:`ocp.solve.certify`).
"""
