"""The real-time side: the control subprocess, its shared memory, channel and client."""
