"""The three source papers: each one's constants and its reproduction, in one subpackage.

``wen2019`` (IPSO, ER10L-C10), ``kou2022`` (LDPSO-BT, KR5 arc), ``chen2023`` (2TPR&2TPS).
Importing a paper's package gives its constants only; :func:`reproduce` imports the
reproduction modules, which use the whole calibration stack.
"""

from __future__ import annotations

SCENARIOS = ("wen2019", "kou2022", "chen2023")
