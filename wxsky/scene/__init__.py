"""The scene stage: cloud blocks, sprites, impostor ring and sky parameters. Pure numpy."""
