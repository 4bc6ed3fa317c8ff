"""Scan programs shipped with softplc: the thesis's case studies as reusable examples."""
