"""Scenes, captures and peers shared by tests and benchmarks; never shipped in the extension.

Each module says what it builds. What lives here is neither product code (it is
not in the extension's zip) nor a test (it asserts nothing): it is what a test
and a benchmark both need, written once.
"""
