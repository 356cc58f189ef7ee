"""Built-in multi-target trackers as plugins."""
