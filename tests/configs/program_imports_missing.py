"""A program module whose own import fails (for the malformed-configuration corpus)."""

import softplc_test_not_installed_package  # noqa: F401  (deliberately missing)
