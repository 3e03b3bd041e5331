"""Settings: the config, presets and cloud model files, each checked by `wxsky.schema`."""
