"""Host side of the wxsky channels: what a simulator host or the CLI uses to talk to the daemon."""
