"""Benchmarks: throughput against peer simulators and learning against the reference policy.

Run from a clone of the repository (this folder is not installed with the package)::

    python -m benchmarks.throughput          # needs the `bench` extra for the peers (MPE2, VMAS)
    python -m benchmarks.learning --level speed --minutes 15   # needs the `train` extra
"""
