"""The papers the workbench reproduces, one plugin package each (``paper000`` ... ``paper003``)."""
