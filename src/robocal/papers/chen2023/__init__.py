"""The reproduction of chen2023 (`reproduce.py`); its constants are in :mod:`robocal.presets.chen2023`."""
