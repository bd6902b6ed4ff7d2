"""The reproduction of kou2022 (`reproduce.py`); its constants are in :mod:`robocal.presets.kou2022`."""
