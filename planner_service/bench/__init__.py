"""Benchmark suites of planning problems (``dexroll bench``): suites as data
(:mod:`.suite`, :mod:`.generators`, ``suites/*.json``), one row per problem and method
(:mod:`.rows`), run by a process pool, a service or Ray (:mod:`.runners`), and a report
(:mod:`.report`). See docs/benchmarks.md.

Importing this package is cheap (the command line imports it); the modules import the
planners when they run.
"""
