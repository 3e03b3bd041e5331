"""The renderer: the only package that imports moderngl."""
