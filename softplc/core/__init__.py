"""The core: tags and data types, the tag database and its write journal, forcing, origins, the clock,
programs and IEC function blocks, expressions, events, the command registry and roles.

It imports nothing of softplc but `softplc.util` (tests/app/test_imports.py checks it).
"""
