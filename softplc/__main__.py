"""`python -m softplc`: the `softplc` command."""

from softplc.entry_point import main

raise SystemExit(main())
