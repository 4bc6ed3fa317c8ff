"""`python -m softplc ARGS`: the same as the `softplc` command."""

from softplc.app.entry_point import main

raise SystemExit(main())
