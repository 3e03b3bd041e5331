"""Outputs to hosts: the shared-memory frame hand-off, the MessagePack-RPC wire format and the
control/state socket server."""
