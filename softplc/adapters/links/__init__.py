"""Links: tags bound to other controllers' OPC UA and Modbus TCP servers (the `links:` section, docs/links.md).

`settings` reads the section and the tags' `link:` keys, `section` checks them for `softplc
check` and adds the `_sys.links.<name>.*` tags and the "link down" alarms; `adapter` runs one
`Link` per remote (`opcua_link`, `modbus_link`), each keeping its bound tags' quality
(`health`), and registers the `links.*` queries and the `links.write` command (`commands`).
"""
