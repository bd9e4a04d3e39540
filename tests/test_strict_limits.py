"""The documented limits of clothlab.untrusted at their boundary: a number of at most 64 characters is read, one
of 65 is refused (README, "strict numbers"), by the field parser and by the YAML loader alike (issue 25: the
limit moved by one survived the suite, which only tried far longer fields); likewise YAML integers of 30 digits,
file size limits, and the non-finite spellings."""

from __future__ import annotations

import re

import pytest

from clothlab.errors import InputError
from clothlab.untrusted import load_yaml_text, parse_number, read_bounded_bytes

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


@pytest.mark.parametrize("text", ["nan", "NaN", "inf", "-inf", "infinity", "+Infinity"])
def test_non_finite_spellings_are_named_as_such(text):
    """Python's float() reads all of these; each is refused as not finite (not as a malformed number)."""
    with pytest.raises(InputError, match=f"value {re.escape(text)} is not finite"):
        parse_number(text)


def test_a_yaml_integer_of_30_digits_is_read_and_one_of_31_refused():
    assert load_yaml_text("seed: " + "9" * 30 + "\n")["seed"] == 10**30 - 1
    assert load_yaml_text("seed: -" + "9" * 30 + "\n")["seed"] == -(10**30 - 1)
    with pytest.raises(InputError, match="an integer of 31 digits"):
        load_yaml_text("seed: " + "1" * 31 + "\n")


def test_a_file_of_exactly_the_limit_is_read_and_one_byte_more_refused(tmp_path):
    path = tmp_path / "data.csv"
    path.write_bytes(b"x" * 100)
    assert read_bounded_bytes(path, limit=100) == b"x" * 100
    with pytest.raises(InputError, match="is 100 bytes; at most 99 are read"):
        read_bounded_bytes(path, limit=99)
