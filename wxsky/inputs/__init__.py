"""Weather inputs that run inside the daemon: live METAR feeds (and, later, cockpit links).

Only modules in this package do input I/O; each input reports through an `InputStats`.
"""
