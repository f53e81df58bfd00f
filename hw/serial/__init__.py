"""The serial I/O board: frames, messages, the backend and the board emulator."""
