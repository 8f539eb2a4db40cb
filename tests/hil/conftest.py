"""Rig runs' tests. The builds they need come from ``firmware_elf`` in tests/conftest.py
(``make test`` makes them first; run alone, it brings them up to date with make)."""
