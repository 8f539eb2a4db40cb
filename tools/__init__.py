"""Repository maintenance, not part of the installed ``utrf``: the generators, the doc writers
and the benchmarks. Run each from the repository's root as ``python -m tools.NAME`` (the
Makefile does); see CONTRIBUTING.md for which one writes what."""
