"""Weather state and its decoders: pure, numpy and stdlib only, no I/O."""
