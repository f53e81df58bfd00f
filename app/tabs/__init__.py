"""The TUI's tabs, one module and one stylesheet each: jog, moves, scope, status, tuning, runs,
latency, identify; the Moves tab's forms in move_forms, end_point_form and path_forms."""
