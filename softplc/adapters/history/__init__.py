"""The historian: records tag values (deadband, swinging-door compression) into a time-partitioned store.

Modules: `settings` (the `history:` section and its rules), `swinging_door` (the compression
algorithm), `recorder` (the adapter), `store` (tables and the writer-side sink), `queries`
(raw, plot, processed, at time), `aggregates` and `bounds` (Part 13 aggregates and bounding
values), `reads` (Part 11 reads page by page), `commands` (the `history.*` commands other adapters
call), `export` (`softplc history export`). See docs/history.md. The core never imports this package.
"""

from softplc.util.lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(__name__, {
    "softplc.adapters.history.settings": ("HistorySettings", "Rule", "TagPolicy", "problems", "tag_rule"),
    "softplc.adapters.history.recorder": ("HistoryRecorder", "TagFilter"),
    "softplc.adapters.history.queries": ("Continuation", "HistoryReader", "Plot", "RawPage", "UnknownTag"),
    "softplc.adapters.history.aggregates": ("Aggregate", "AggregateConfig", "Flags", "Result", "Sample"),
    "softplc.adapters.history.swinging_door": ("SwingingDoor",),
})
