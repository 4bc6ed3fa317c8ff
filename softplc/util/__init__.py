"""Small utilities every layer may use: durations, timestamps, suggestions, console tables, logging helpers."""
