"""The reproduction of wen2019 (`reproduce.py`); its constants are in :mod:`robocal.presets.wen2019`."""
