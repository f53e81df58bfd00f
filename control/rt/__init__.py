"""The code the control process runs, and nothing else: the 1 kHz loop and its components,
the laws, the typed commands and events and their wire, the shared-memory layout, segments
and seqlock, and the process's entry point (``python -m control.rt.process``).

``tests/control/rt/test_process.py`` reads what the control process imports: this package,
``hw`` and the standard library, and numpy-free where the tick runs.
"""
