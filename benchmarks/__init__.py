"""Reproducible benchmarks of the stack; ``python -m benchmarks.run`` writes BENCHMARKS.md.

Each benchmark is a module with ``run(quick: bool) -> dict``: it measures and returns plain data
(JSON-serialisable), nothing else. :mod:`benchmarks.report` turns the data into Markdown and
:mod:`benchmarks.run` runs them one after the other (never in parallel: the numbers are
CPU-bound on small machines) and writes ``BENCHMARKS.md`` and ``benchmarks/results.json``.
"""
