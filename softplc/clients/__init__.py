"""The client side: command-line tools that talk to a running plant over OPC UA.

`login` (endpoint, security, user: one way for every tool), `session` (an open session with the
plant's namespace and tag types), `door_client` (calling runtime commands remotely); one folder
per command family, each with its `cli.py`: `tags` (read, write, watch, force), `alarms`, `audit`,
`apply` (online change), `robot_agent` (a robot on its own computer).
Clients import no server module (tests/app/test_imports.py).
"""
