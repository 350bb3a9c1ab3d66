"""The restricted quantity parser of :mod:`r2rsim.units`.

The parser replaced pint's expression evaluator; pint stays the reference. Every quantity
string in the repository, and every spelling in the unit table, must read exactly as pint
reads it; hostile strings must fail fast with a :class:`QuantityError`.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from r2rsim import units
from r2rsim.units import DIMENSIONS, QuantityError, parse_quantity

REPO = Path(__file__).resolve().parents[1]
REL = 1e-12

# Spellings the parser accepts on purpose although pint does not, and pint's name for them.
EXTENSIONS = {"rev": "revolution"}
# Quantity strings of the repository that must be refused (they test the error path).
KNOWN_REJECTED = {"1.5 meterz"}


@pytest.fixture(scope="module")
def ureg():
    import pint

    return pint.UnitRegistry(autoconvert_offset_to_baseunit=True)


def _pint_si(ureg, text: str) -> tuple[float, dict]:
    """pint's reading of ``text``: value in SI base units and dimensions."""
    q = ureg.Quantity(text)
    if not isinstance(q, ureg.Quantity):
        return float(q), {}
    b = q.to_base_units()
    return float(b.magnitude), _norm(dict(b.dimensionality))


def _norm(dims: dict) -> dict:
    return {str(k): float(v) for k, v in dims.items() if v}


def _same(ours: tuple[float, dict], ref: tuple[float, dict]) -> bool:
    return math.isclose(ours[0], ref[0], rel_tol=REL, abs_tol=0.0) and _norm(ours[1]) == ref[1]


# --- every quantity string in the repository --------------------------------------------------
_STARTS_NUMERIC = re.compile(r"^\s*[+-]?(?:[0-9]|\.[0-9])")
# A string literal that starts with a number and goes on with a unit: "50 um", '300 m/min'.
_LITERAL = re.compile(
    r"""(?<![\w.])["']([+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)"""
    r"""(?:[eE][+-]?[0-9]+)?[ ]?[A-Za-z%µμ°][^"'\n]{0,40})["']"""
)


def _strings(node):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _strings(k)
            yield from _strings(v)
    elif isinstance(node, list):
        for v in node:
            yield from _strings(v)
    elif isinstance(node, str):
        yield node


def _repository_quantities() -> dict[str, str]:
    """Quantity strings of lines/, scenarios/ and tests/ -> the first file using each."""
    found: dict[str, str] = {}
    files = sorted(REPO.glob("lines/*.yaml")) + sorted(REPO.glob("scenarios/**/*.yaml"))
    for path in files:
        for doc in yaml.safe_load_all(path.read_text()):
            for s in _strings(doc):
                if _STARTS_NUMERIC.match(s):
                    try:
                        float(s)  # a bare number never reaches the unit parser
                    except ValueError:
                        found.setdefault(s, str(path.relative_to(REPO)))
    for path in sorted(REPO.glob("tests/**/*.py")):
        # files of hostile strings (this one's below, the fuzzers') are not quantities of use,
        # nor are the expected messages of the sweep, worker, set-point and tutorial tests
        # ("1 of 3 combinations is invalid", "2 local worker processes", "20 s simulated")
        if path.name in (
            Path(__file__).name,
            "test_fuzz.py",
            "test_input_robustness.py",
            "test_sweep.py",
            "test_sweep_workers.py",
            "test_break_setpoint.py",
            "test_tutorial.py",
        ):
            continue
        for m in _LITERAL.finditer(path.read_text()):
            found.setdefault(m.group(1), str(path.relative_to(REPO)))
    return found


REPO_QUANTITIES = _repository_quantities()


def test_repository_quantities_were_found():
    # a guard against the collection silently finding nothing
    assert len(REPO_QUANTITIES) > 100
    assert {"50 um", "300 m/min", "0.5 kg*m^2", "90 deg", "2000 N*s/m"} <= set(REPO_QUANTITIES)


@pytest.mark.parametrize("text", sorted(REPO_QUANTITIES))
def test_repository_quantity_reads_as_pint_reads_it(ureg, text):
    # Only strings our parser accepts are handed to pint: a hostile string added to some
    # test file later must not hang this test inside pint.
    try:
        ours = units._parse_text(text.strip())
    except units._Unreadable as exc:
        assert text in KNOWN_REJECTED, f"{text!r} ({REPO_QUANTITIES[text]}) is refused: {exc}"
        return
    assert text not in KNOWN_REJECTED
    assert _same(ours, _pint_si(ureg, text)), text


# --- every spelling in the table, with exponents, against pint --------------------------------
def test_table_spellings_and_powers_match_pint(ureg):
    bad = []
    n = 0
    for name in units._UNITS:
        ref_name = EXTENSIONS.get(name, name)
        for e in (1, 2, -1, 3, -4):
            ours = units._parse_text(f"1 {name}^{e}")
            if not _same(ours, _pint_si(ureg, f"1 {ref_name}**{e}")):
                bad.append((name, e, ours))
            n += 1
    assert not bad, bad
    assert n > 1500


def test_table_has_the_promised_units():
    for name in (
        "m",
        "mm",
        "um",
        "µm",
        "μm",
        "km",
        "g",
        "kg",
        "mg",
        "s",
        "ms",
        "us",
        "min",
        "h",
        "Hz",
        "kHz",
        "N",
        "kN",
        "mN",
        "Pa",
        "kPa",
        "MPa",
        "GPa",
        "bar",
        "mbar",
        "J",
        "W",
        "kW",
        "rad",
        "mrad",
        "deg",
        "°",
        "rpm",
        "rev",
        "%",
        "meter",
        "metres",
        "second",
        "sec",
        "newton",
        "pascal",
        "gram",
        "kilogram",
        "hour",
        "minute",
        "hertz",
        "degree",
        "degrees",
        "radian",
        "revolution",
    ):
        assert name in units._UNITS, name


COMPOUNDS = [
    # (ours, the same in pint's syntax)
    ("2000 N*s/m", None),
    ("1 m/s/s", None),
    ("0.5 kg*m^2", None),
    ("5 N m", None),
    ("5 N·m", None),
    ("5 N⋅m", "5 N*m"),
    ("1 kg/(m*s)", None),
    ("1 kg/(m s)", None),
    ("1 kg/m s", None),
    ("3 m/s*kg", None),
    ("1390 kg/m^3", None),
    ("1390 kg/m**3", None),
    ("1 kg·m²", None),
    ("2 s⁻¹", None),
    ("2 s^-1", None),
    ("2 s^(-1)", None),
    ("2 s^(−1)", "2 s**-1"),
    ("1 1/min", None),
    ("5 /s", None),
    ("5 1/s", None),
    ("3 m per min", None),
    ("50um", None),
    ("1e3 mm", None),
    ("1e+3m", None),
    ("-2.5e-3 N", None),
    (".5 m", None),
    ("5. m", None),
    ("+5 m", None),
    ("1_000 m", None),
    ("90°", None),
    ("50 %", None),
    ("50%", None),
    ("5 ‰", None),
    ("100 rpm", None),
    ("3 rev/min", "3 rpm"),
    ("1 (m/s)^2", None),
    ("1 N*m*s", None),
    ("1 mN*m", None),
    ("1 daN/m", None),
    ("1 kW*h", None),
    ("100 Pa*s", None),
    ("1 m/(s)", None),
    ("1 (N)", None),
    ("5\u00a0um", "5 um"),
    ("1 GPa", None),
    ("1 degrees/s", None),
    # names outside the table go to pint one at a time
    ("3 ft", None),
    ("2 inch", None),
    ("1 lbf", None),
    ("1 psi", None),
    ("5 ft*lbf", None),
    ("1 lbf/inch", None),
    ("1 ft/min", None),
    ("1 micron", None),
    ("1 t", None),
    ("1 kgf", None),
    ("1 ppm", None),
    ("1 dimensionless", None),
    ("1 mil", None),
]


@pytest.mark.parametrize("text, ref", COMPOUNDS, ids=[c[0] for c in COMPOUNDS])
def test_compound_expressions_match_pint(ureg, text, ref):
    assert _same(units._parse_text(text), _pint_si(ureg, ref or text))


def test_pint_sees_only_single_identifiers(monkeypatch):
    seen = []
    original = units._pint_unit

    def spy(name):
        seen.append(name)
        return original(name)

    monkeypatch.setattr(units, "_pint_unit", spy)
    assert parse_quantity("5 ft*lbf", "torque") == pytest.approx(5 * 0.3048 * 4.4482216152605)
    with pytest.raises(QuantityError):
        parse_quantity("1 ft/(0)", "speed")
    with pytest.raises(QuantityError, match="unknown unit 'wibble'"):
        parse_quantity("1 wibble", "length")
    assert seen and all(re.fullmatch(r"[A-Za-z_µμ][A-Za-z0-9_µμ]*", s) for s in seen), seen
    assert "ft" in seen and "lbf" in seen


def test_offset_and_logarithmic_units_are_refused():
    with pytest.raises(QuantityError, match="offset or logarithmic"):
        parse_quantity("20 degC", "dimensionless")
    with pytest.raises(QuantityError, match="offset or logarithmic"):
        parse_quantity("3 dB", "dimensionless")


# --- public behaviour kept from the pint-based version ----------------------------------------
@pytest.mark.parametrize(
    "value, dimension, expected",
    [
        ("50 um", "length", 50e-6),
        ("300 m/min", "speed", 5.0),
        ("4.5 GPa", "pressure", 4.5e9),
        ("0.5 kg*m^2", "inertia", 0.5),
        ("90 deg", "angle", math.pi / 2),
        ("100 rpm", "angular_speed", 100 * 2 * math.pi / 60),
        ("1 kHz", "frequency", 1000.0),
        ("2000 N*s/m", "damping", 2000.0),
        ("1 Hz", "angular_speed", 1.0),
        ("3 rad/s", "angular_speed", 3.0),
        ("50 %", "dimensionless", 0.5),
        ("0.5 %", "angle", 0.005),
        ("1e3", "length", 1000.0),
        ("  7  ", "time", 7.0),
        (2, "force", 2.0),
        (0.25, "time", 0.25),
        ("1 rev", "angle", 2 * math.pi),
        ("-9.81 m/s^2", "acceleration", -9.81),
        ("1.0e-4 N*m*s", "viscous_torque", 1e-4),
    ],
)
def test_values(value, dimension, expected):
    assert parse_quantity(value, dimension) == pytest.approx(expected, rel=REL)


def test_booleans_types_and_non_finite_numbers_are_refused():
    with pytest.raises(QuantityError, match="got a boolean"):
        parse_quantity(True, "length")
    with pytest.raises(QuantityError, match="got list"):
        parse_quantity([1], "length")
    for bad in ("inf", "nan", float("inf"), float("nan"), "1e999 m", "1e308 km"):
        with pytest.raises(QuantityError, match="not a finite number"):
            parse_quantity(bad, "length")


def test_wrong_dimension_message():
    with pytest.raises(QuantityError) as info:
        parse_quantity("3 N", "length")
    assert str(info.value) == (
        "'3 N' has dimension [length] * [mass] / [time] ** 2, expected a length (e.g. '1.5 m')"
    )
    with pytest.raises(QuantityError, match=r"has dimension dimensionless, expected a speed"):
        parse_quantity("5 %", "speed")
    with pytest.raises(QuantityError, match=r"has dimension 1 / \[time\], expected an? angle"):
        parse_quantity("5 rpm", "angle")


def test_unreadable_message_style():
    with pytest.raises(QuantityError) as info:
        parse_quantity("1.5 meterz", "length")
    assert str(info.value) == (
        "cannot read '1.5 meterz' as a quantity (unknown unit 'meterz'); write e.g. '1.5 m'"
    )


@pytest.mark.parametrize("dimension", sorted(DIMENSIONS))
def test_dimension_table_agrees_with_the_parser(ureg, dimension):
    # the expected dimension is read from the SI unit by the new parser; it must spell the
    # same as the pint dimensionality kept in DIMENSIONS, and each example must read as in pint
    pint_dims, _, example = DIMENSIONS[dimension]
    assert units._format_dims(units._expected_dims(dimension)) == (pint_dims or "dimensionless")
    assert parse_quantity(example, dimension) == pytest.approx(_pint_si(ureg, example)[0], rel=REL)


# --- hostile strings: a QuantityError, quickly ------------------------------------------------
HOSTILE = [
    "10**10**10 m",
    "1/0 m",
    "5 m/0",
    "(5 m",
    "2**1000000 m",
    "9" * 400 + " m",
    "1 " + "m " * 5000,
    "x" * 10_000,
    "5 " + "m" * 9_998,
    "5\x00 m",
    "\x00",
    "",
    "5 m\u202e",
    "\U0001f4a5 m",
    "5 \u2603",
    "5 m\ud800",
    "5 \u00e9",
    "5 m\u0301",
    "1 kg/((m*s))",
    "1 " + "(" * 40 + "m" + ")" * 40,
    "1 ((m)",
    "1 m)",
    "1 ()",
    "1 (m))",
    "1 m^99999999999999999999",
    "1 m^5",
    "1 m^2^2",
    "1 m^2.5",
    "1 m^",
    "1 m**",
    "1 m^x",
    "1 m^(2",
    "1e99999 m",
    "1" * 31 + " m",
    "1 m/",
    "1 /",
    "1 */m",
    "1 m**/s",
    "5^2 m",
    "5 2 m",
    "5 m 2",
    "m",
    "m/s",
    "- 5 m",
    "5 m,",
    "1,5 m",
    "1 000 m",
    "5 m = 3",
    "__import__('os') m",
    "5 m; import os",
    "5 m\n6 s",
    "5 ${HOME}",
    "5 m[0]",
    "5 m.s",
    "5 1.0/s",
    "5 0/s",
    "5 m/1",
    "5 per",
    "5 m per",
    "5 m^-",
    "1 m" + "*m" * 40,
    "1 " + "/".join(["m"] * 40),
    "0x10 m",
    "1e m",
    "5 m @ 3",
    "5 m#",
    "1 " + "m^4 " * 20,
]


def test_hostile_strings_fail_fast_with_a_quantity_error():
    t0 = time.perf_counter()
    for text in HOSTILE:
        with pytest.raises(QuantityError):
            parse_quantity(text, "length")
    elapsed = time.perf_counter() - t0
    assert elapsed < 1.0, f"{len(HOSTILE)} hostile strings took {elapsed:.2f} s"


def test_extreme_units_give_a_quantity_error_not_an_arithmetic_exception():
    # factors that overflow to inf or underflow to 0 (pint fallback: yocto/yotta parsecs)
    for text in (
        "1 Ypc^4 Ypc^4 Ypc^-4 Ypc^-3",
        "1 /(ym^4 ym^4 ym^4 ym^4) ym^4 ym^4 ym^4 ym^4 ym",
        "1 (Ypc^4 Ypc^4)^4 Ypc^-4 Ypc^-4 Ypc^-4 Ypc^-4 Ypc^-4 Ypc^-4 Ypc^-4 Ypc^-3",
    ):
        with pytest.raises(QuantityError, match="finite|out of range"):
            parse_quantity(text, "length")


def test_long_strings_are_refused_with_a_short_message():
    with pytest.raises(QuantityError, match=r"longer than 100 characters") as info:
        parse_quantity("1 " + "m " * 5000, "length")
    assert len(str(info.value)) < 200


def test_nested_parentheses_message():
    with pytest.raises(QuantityError, match="cannot be nested"):
        parse_quantity("1 kg/((m*s))", "damping")


def test_commas_are_refused_not_dropped():
    # pint drops commas, so "1,5 m" would be 15 m
    with pytest.raises(QuantityError, match="decimal point"):
        parse_quantity("1,5 m", "length")


def test_the_common_path_does_not_import_pint():
    code = (
        "import sys; from r2rsim.units import parse_quantity; "
        "parse_quantity('50 um','length'); parse_quantity('300 m/min','speed'); "
        "parse_quantity('0.5 kg*m^2','inertia'); parse_quantity('100 rpm','angular_speed'); "
        "print('pint' in sys.modules, 'numpy' in sys.modules)"
    )
    p = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True
    )
    assert p.stdout.split() == ["False", "False"]
