"""`python -m softplc ARGS`: the same as the `softplc` command."""

from softplc.app.cli import main

raise SystemExit(main())
