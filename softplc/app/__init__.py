"""The application: the `softplc` command line, adapter discovery, the composition root (Runtime), stop signals."""
