"""Widgets shared by the tabs: header and E-stop lamp, scope plot, limit bar, live text,
validated fields, dialogs."""
