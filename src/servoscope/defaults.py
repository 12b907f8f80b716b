"""servoscope's defaults, in one home.

Every stage, the command line and the digital twin take their default marker colours and
shared thresholds from here, so that changing one changes it everywhere (and the twin renders
what the tracker looks for by default, which the tests then vary on purpose).
"""

from __future__ import annotations

# -- markers -------------------------------------------------------------------------------------
#: Leading-edge sticker (matplotlib's tab:red, as in the paper's red sticker).
LEAD_COLOUR = "#d62728"
#: Trailing-edge sticker (tab:green).
TRAIL_COLOUR = "#2ca02c"
#: The input-start LED, lit.
LED_COLOUR = "#ffd400"
