"""A commanding client to be killed mid-move, as a script for ``python -c SCRIPT SOCKET``: it
attaches to the service as "doomed", takes command, starts a slow go_to of In/Out by 40 mm,
prints its name and waits on stdin for its end."""

DOOMED = """
import sys
from control.client import ControlClient
client = ControlClient.attach(sys.argv[1], name="doomed")
client.take_command()
q = list(client.status().position)
q[0] += 40.0
client.go_to(q, speed=0.1)
print(client.name, flush=True)
sys.stdin.read()
"""
