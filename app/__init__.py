"""servodesk's operator side: the Textual TUI and the ``servodesk`` command line."""
