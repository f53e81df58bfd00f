"""The TUI's tabs, one module each: jog, moves, scope, status, tuning, runs, latency."""
