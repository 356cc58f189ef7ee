"""Built-in motion models as plugins."""
