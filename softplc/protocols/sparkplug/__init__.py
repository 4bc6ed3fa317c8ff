"""Sparkplug B 3.0.0 (Eclipse, 2022): the wire pieces an edge node needs, shared by whoever speaks it.

- `sparkplug_b.proto`: the payload definition, written from the specification's chapter 6;
  `sparkplug_b_pb2.py` is generated from it and committed (scripts/generate-sparkplug.sh
  regenerates it; the `protobuf` runtime it needs is pinned in pyproject.toml).
- `datatypes`: the Sparkplug datatypes, which tag type maps to which, and how integers travel.
- `topics`: the topic namespace `spBv1.0/<group>/<message type>/<edge node>[/<device>]` and
  the primary host's `spBv1.0/STATE/<host>`.
- `payloads`: births, data, deaths and commands encoded and decoded (imports protobuf).
- `sequence`: `seq` (0–255, NBIRTH = 0) and `bdSeq` (+1 per connect, kept on disk).

Only `payloads` imports protobuf; the rest is light enough for a configuration check.
"""
