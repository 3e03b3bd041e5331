"""The engine: the fixed stage order from weather to frame plan, and the ring schedule."""
