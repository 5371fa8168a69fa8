"""'align init': the commented session.toml for the instruments named is valid TOML that the
shipped JSON Schema accepts, as are the synthetic sessions' session.toml files; the schema
knows every key the loader knows (and refuses what the loader refuses)."""

from __future__ import annotations

import re
import tomllib

import jsonschema
import pytest

from align.contract import schema
from align.errors import InputError
from align.session.check import _plain
from align.session.config import KEYS, TOP_KEYS
from align.session.template import session_template
from synth.session import SessionSpec
from tests.conftest import write_unrendered


def _validator():
    s = schema("session-toml")
    jsonschema.Draft7Validator.check_schema(s)
    return jsonschema.Draft7Validator(s)


@pytest.mark.parametrize("kw", [
    {"cameras": ["A", "B"], "gonio": True, "tumble": True, "static": True},
    {"cameras": ["A"]}, {"gonio": True}, {"tumble": True},
    {"cameras": ["A", "B", "C"], "tumble": True},
])
def test_the_template_is_valid_against_the_schema(kw):
    text = session_template(**kw)
    d = tomllib.loads(text)
    errors = list(_validator().iter_errors(_plain(d)))
    assert errors == [], [e.message for e in errors]
    assert "[tolerance]" in text and "decision" in text  # documented, commented out
    # every key the template writes or comments out carries a unit or a default in words
    for line in text.splitlines():
        code = line.split("#")[0]
        if ("_deg" in code or "_arcsec =" in code) and "up =" not in code:  # poses: in
            # their table's header comment
            assert "[°]" in line or "[″]" in line or "faces" in line, line


def test_the_template_names_every_key_of_its_sections():
    """Every key the loader knows in the sections written (set or commented out), and every
    top-level key: a user sees the whole vocabulary with its unit and default."""
    text = session_template(["A", "B"], gonio=True, tumble=True, static=True)
    keys = set(TOP_KEYS) | {k for keys in KEYS.values() for k in keys}
    missing = sorted(k for k in keys if not re.search(rf"^#? ?\[*{k}\b|[\s.]{k} =|\.{k}\]", text,
                                                      flags=re.M))
    assert missing == [], missing


def test_the_synthetic_sessions_are_valid_against_the_schema(tmp_path):
    for k, spec in enumerate([SessionSpec(seed=1), SessionSpec(seed=2, reverse_run=True)]):
        write_unrendered(tmp_path / f"s{k}", spec)  # session.toml is read, not the images
        d = tomllib.loads((tmp_path / f"s{k}" / "session.toml").read_text())
        errors = list(_validator().iter_errors(_plain(d)))
        assert errors == [], [e.message for e in errors]


def test_the_schema_knows_the_loaders_keys():
    props = schema("session-toml")["properties"]
    assert set(props) == TOP_KEYS | {"tolerance"}
    for section, keys in KEYS.items():
        node = props[section]
        if section in ("cameras", "views"):
            node = node["additionalProperties"]
        elif section == "images":
            node = node["items"]
        assert set(node["properties"]) == keys, section


@pytest.mark.parametrize("bad", [
    'housing = "w"', "scale_sign = \"+,-\"", "roll_arcsec = 1e9", 'direction = "up"',
    "statik = 1"])
def test_the_schema_refuses_what_the_loader_refuses(bad):
    base = {"calibration": {"static": "t.csv"}, "cameras": {"A": {}},
            "views": {"A": {"right": "+X", "up": "+Z"}},
            "images": [{"file": "a.png", "housing": "x", "view": "A", "nominal": "horizontal"}],
            "goniometer": {"log": "g.csv", "faces": ["ref", "y", "x", "z"]}}
    assert list(_validator().iter_errors(base)) == []
    key, _, value = bad.partition(" = ")
    value = tomllib.loads(f"v = {value}")["v"]
    where = {"housing": base["images"][0], "scale_sign": base["calibration"],
             "roll_arcsec": base["cameras"]["A"], "direction": base["goniometer"],
             "statik": base["calibration"]}[key]
    where[key] = value
    assert list(_validator().iter_errors(base)) != []


def test_init_refuses_nothing_named_or_a_platform_without_calibration():
    with pytest.raises(InputError, match="name at least one"):
        session_template()
    with pytest.raises(InputError, match="--tumble"):
        session_template(static=True)
    with pytest.raises(InputError, match="each camera once"):
        session_template(["A", "A"])
