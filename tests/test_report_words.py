"""The report's words come from the Jinja2 templates of pbmdem/data/report_templates, filled from a
dict of the run's numbers (pbmdem.report.words)."""

from __future__ import annotations

import jinja2
import pytest

from pbmdem.report import words


def test_every_template_parses():
    names = words.ENV.list_templates(extensions=["j2"])
    assert {"findings.rst.j2", "speed.j2", "feed.j2", "lumping.j2", "target.j2"} <= set(names)
    for name in names:
        words.ENV.get_template(name)


def test_a_number_the_dict_lacks_is_an_error_not_a_gap():
    numbers = {
        "feed": "fine",
        "batch": "8 min",
        "lo": {"rpm": 300.0, "d10": 1e-3, "d50": 2e-3, "d90": 3e-3},
        "hi": {"rpm": 1200.0, "d10": 1.1e-3, "d50": 2.5e-3, "d90": 3.2e-3},
        "change": 0.25,
        "peak": None,
        "peak_d50": None,
        "spread": 1e-5,
        "outside": [1200.0],
        "n": 4,
    }
    text = words.paragraph("speed", **numbers)
    assert text.startswith(
        "**Impeller speed.** With the ``fine`` feed, raising the impeller speed from 300 to 1200 rpm"
    )
    assert "from d50 = 2.00 mm to 2.50 mm (+25.0 %)" in text
    assert "more collisions make larger granules. The surrogate's members disagree" in text
    assert text.endswith("at 1 of 4 speeds (1200 rpm): treat those as extrapolations.")
    assert "\n" not in text and "  " not in text
    del numbers["spread"]
    with pytest.raises(jinja2.UndefinedError, match="spread"):
        words.paragraph("speed", **numbers)


def test_folding_joins_lines_and_keeps_a_marked_final_space():
    assert words.fold("  one\n\n    two.\n") == "one two."
    assert words.fold("one.\n" + words.ENV.globals["space"]) == "one. "
