"""The engine: the scan cycle and its gate, stall detection, system tags, statistics, retained values,
program instances and program control, runtime commands, online change, and the `runtime:` section.

It imports the core, the configuration and the utilities only (tests/app/test_imports.py).
"""
