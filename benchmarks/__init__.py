"""End-to-end benchmark scenarios: ``python -m benchmarks NAME``.

Each scenario prints a table and, as its last line, one JSON object with its figures.
"""
