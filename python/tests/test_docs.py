"""The docstrings that list words of the command line are composed from the native module's lists
(calib's registries), and agree with ``robocal calibrate --help``."""

from __future__ import annotations

import robocal
from robocal import _robocal


def test_calibrate_docstring_names_every_cause_and_learned_kind(cli) -> None:
    doc = robocal.calibrate.__doc__ or ""
    assert "{model_words}" not in doc
    help_text = cli.run("calibrate", "--help").stdout
    # The two hand-written lists of issue 23 had lost these.
    assert {"transmission_error", "link_deflection"} <= set(_robocal.CAUSES)
    for word in [*_robocal.CAUSES, *_robocal.LEARNED_KINDS]:
        assert word in doc, word
        assert word in help_text, word
    # A cause at only some of its joints (issue 25): the syntax is named in both.
    assert "@2,4" in doc and "@2,4" in help_text
