"""The Sparkplug B edge node: the plant's tags published to SCADA over MQTT (docs/sparkplug.md).

`section` and `settings` read the `sparkplug:` section (devices by template or tag pattern);
`edge_node` is the adapter (sessions, births, data, deaths); `changes` gathers what changed per
device; `commands` checks and applies NCMD/DCMD; `store` keeps data on disk while the primary host is away; `status` the
`_sys.sparkplug.*` tags and figures.
"""
