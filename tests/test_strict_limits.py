"""The documented limits of clothlab.strict at their boundary: a number of at most 64 characters is read, one
of 65 is refused (README, "strict numbers"), by the field parser and by the YAML loader alike (issue 25: the
limit moved by one survived the suite, which only tried far longer fields)."""

from __future__ import annotations

import pytest

from clothlab.errors import InputError
from clothlab.strict import load_yaml_text, parse_number

SIXTY_FOUR = "0." + "25" * 31  # 64 characters
assert len(SIXTY_FOUR) == 64


@pytest.mark.parametrize("text", [SIXTY_FOUR, "-" + SIXTY_FOUR[:-1], "1" * 60 + "e-50"])
def test_a_number_of_64_characters_is_read(text):
    assert len(text) == 64
    assert parse_number(text) == pytest.approx(float(text), rel=1e-15)
    assert load_yaml_text(f"x: {text}\n")["x"] == pytest.approx(float(text), rel=1e-15)


@pytest.mark.parametrize("text", [SIXTY_FOUR + "5", "-" + SIXTY_FOUR, "1" * 61 + "e-50"])
def test_a_number_of_65_characters_is_refused(text):
    assert len(text) == 65
    with pytest.raises(InputError, match="has 65 characters; a number has at most 64") as info:
        parse_number(text, field="kd")
    assert "kd" in str(info.value)
    with pytest.raises(InputError, match="65 characters"):
        load_yaml_text(f"x: {text}\n", path="fabric.yaml")
