"""Online change: a running plant re-reads its file and swaps changed programs between two cycles.

`diff` (what changed), `fresh` (modules loaded anew), `change` (check, carry state over, swap).
"""
