"""Fleets of robots: nightly jobs on Dask (``run``), the history they append to (``history``),
wear trends read from it (``trend``). Manifests are described in docs/fleet.md."""
