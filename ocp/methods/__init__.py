"""Other planning methods: the paper's greedy method.
"""
