"""The applications: the daemon, its control commands, frame publishing, snapshot and bench."""
