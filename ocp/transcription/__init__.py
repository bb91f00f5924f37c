"""Transcription: direct collocation (Hermite-Simpson), the NLP's parameters by name, the grasp
model and the NLP assembled from blocks.
"""
