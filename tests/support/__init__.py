"""Helpers several test packages share (importable as ``support``: tests/ is on sys.path
through its conftest.py)."""
