"""One sky shared by several daemons: the sky master's state as messages, and a channel's
clock following the master's (pure); the bus that carries them (`zenoh_bus.py`, the only
Zenoh user). docs/channels.md."""
