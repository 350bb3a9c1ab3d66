"""Quantities in input files: bare numbers are SI, strings carry units and are parsed once.

``parse_quantity("300 m/min", "speed")`` returns 5.0. Nothing downstream of the schema sees
anything but SI floats.

Quantity strings are read by a small restricted parser, not by pint's expression evaluator:
pint evaluates arbitrary arithmetic (``"10**10**10 m"`` never returns, ``"1/0 m"`` raises
ZeroDivisionError) and importing it costs a large part of a second. The grammar::

    quantity  := [sign] number [space] [units]
    number    := digits ["." [digits]] | "." digits, then optionally e|E [sign] digits
                 (at most 30 characters before the power of ten, at most 3 digits in it;
                 "_" may separate digits as in Python)
    units     := operand (operator operand)*
    operator  := "*" | "·" | "⋅" | "/" | "per" | space     (a space multiplies: "N m")
    operand   := name [power] | "(" operand (operator operand)* ")" [power] | "1" (before "/")
    power     := ("^" | "**") [sign] digits | ("^" | "**") "(" [sign] digits ")"
                 | superscripts such as "²", "⁻¹"     (whole, |exponent| <= 4; sign: + - −)
    name      := a letter, "_", "µ", "μ" or "°" followed by letters, digits, "_", "µ", "μ";
                 or "%" or "‰"

``*``, ``/`` and juxtaposition have equal precedence and group left to right, as in pint:
``"N*s/m"`` is N·s/m, ``"m/s/s"`` is m/s², ``"kg/m s"`` is kg·s/m; a power binds tighter
(``"m/s^2"`` is m/s²). Parentheses group a denominator, ``"kg/(m*s)"``; they do not nest.
Commas are refused (pint drops them, so ``"1,5 m"`` would silently become 15 m). A string
is at most 100 characters long.

Names are looked up in a built-in table of SI-consistent units (:data:`_UNITS`). A name
not in the table is handed, alone and only once it has been checked to be an identifier, to
pint (``ureg.Quantity(1, name)``), so that feet, inches, lbf, psi... still work; only then
is pint imported.
"""

from __future__ import annotations

import functools
import math
import re

# Dimensions accepted by schema fields: name -> (pint dimensionality string, SI unit, example).
DIMENSIONS: dict[str, tuple[str, str, str]] = {
    "length": ("[length]", "m", "1.5 m"),
    "speed": ("[length] / [time]", "m/s", "300 m/min"),
    "acceleration": ("[length] / [time] ** 2", "m/s^2", "0.5 m/s^2"),
    "time": ("[time]", "s", "1 ms"),
    "frequency": ("1 / [time]", "Hz", "1 kHz"),
    "force": ("[length] * [mass] / [time] ** 2", "N", "260 N"),
    "force_rate": ("[length] * [mass] / [time] ** 3", "N/s", "100 N/s"),
    "stiffness": ("[mass] / [time] ** 2", "N/m", "2000 N/m"),
    "damping": ("[mass] / [time]", "N*s/m", "50 N*s/m"),
    "pressure": ("[mass] / [length] / [time] ** 2", "Pa", "4.5 GPa"),
    "density": ("[mass] / [length] ** 3", "kg/m^3", "1390 kg/m^3"),
    "mass": ("[mass]", "kg", "10 kg"),
    "inertia": ("[length] ** 2 * [mass]", "kg*m^2", "0.5 kg*m^2"),
    "torque": ("[length] ** 2 * [mass] / [time] ** 2", "N*m", "50 N*m"),
    "viscous_torque": ("[length] ** 2 * [mass] / [time]", "N*m*s", "0.01 N*m*s"),
    "angle": ("", "rad", "90 deg"),
    "angular_speed": ("1 / [time]", "rad/s", "100 rpm"),
    "dimensionless": ("", "1", "0.001"),
    "inverse_area": ("1 / [length] ** 2", "1/m^2", "0.02 1/m^2"),
}

MAX_CHARS = 100  # longest quantity string accepted
_MAX_MANTISSA = 30  # characters of a number before its power of ten
_MAX_POWER_OF_TEN = 3  # digits of that power of ten
_MAX_EXPONENT = 4  # |n| in m^n


class QuantityError(ValueError):
    """A quantity string could not be parsed or has the wrong dimension."""


class _Unreadable(Exception):
    """Internal: why a string is not a quantity; turned into a :class:`QuantityError`."""


# --- the unit table --------------------------------------------------------------------------
# Dimensions are dicts {pint dimension name: exponent}, empty for dimensionless. Angles are
# dimensionless with the radian as their SI unit, as in pint, so "90 deg" is pi/2 and "100 rpm"
# is 10.47 (rad/s), exactly what the pint-based parser returned.
_L, _M, _T = "[length]", "[mass]", "[time]"

_SI_PREFIXES: dict[str, float] = {
    "p": 1e-12,
    "n": 1e-9,
    "u": 1e-6,
    "\u00b5": 1e-6,
    "\u03bc": 1e-6,
    "m": 1e-3,
    "c": 1e-2,
    "d": 1e-1,
    "da": 1e1,
    "h": 1e2,
    "k": 1e3,
    "M": 1e6,
    "G": 1e9,
    "T": 1e12,
}
_LONG_PREFIXES: dict[str, float] = {
    "pico": 1e-12,
    "nano": 1e-9,
    "micro": 1e-6,
    "milli": 1e-3,
    "centi": 1e-2,
    "deci": 1e-1,
    "deca": 1e1,
    "deka": 1e1,
    "hecto": 1e2,
    "kilo": 1e3,
    "mega": 1e6,
    "giga": 1e9,
    "tera": 1e12,
}
_ANGLE_PREFIXES = ("n", "u", "\u00b5", "\u03bc", "m")
_ANGLE_LONG_PREFIXES = ("nano", "micro", "milli")

# (symbols, long names, SI factor, dimensions, symbol prefixes, long-name prefixes, plural)
_BASE_UNITS: tuple = (
    (("m",), ("meter", "metre"), 1.0, {_L: 1}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("g",), ("gram",), 1e-3, {_M: 1}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("s",), ("second",), 1.0, {_T: 1}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("sec",), (), 1.0, {_T: 1}, (), (), False),
    (("min",), ("minute",), 60.0, {_T: 1}, (), (), True),
    (("h", "hr"), ("hour",), 3600.0, {_T: 1}, (), (), True),
    (("Hz",), ("hertz",), 1.0, {_T: -1}, _SI_PREFIXES, _LONG_PREFIXES, False),
    (("N",), ("newton",), 1.0, {_L: 1, _M: 1, _T: -2}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("Pa",), ("pascal",), 1.0, {_M: 1, _L: -1, _T: -2}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("bar",), (), 1e5, {_M: 1, _L: -1, _T: -2}, ("m", "k"), (), False),
    (("J",), ("joule",), 1.0, {_L: 2, _M: 1, _T: -2}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("W",), ("watt",), 1.0, {_L: 2, _M: 1, _T: -3}, _SI_PREFIXES, _LONG_PREFIXES, True),
    (("rad",), ("radian",), 1.0, {}, _ANGLE_PREFIXES, _ANGLE_LONG_PREFIXES, True),
    (("deg", "\u00b0"), ("degree",), math.pi / 180, {}, (), (), True),
    # "rev" is not a pint name; it is added here because "1 rev" reads naturally.
    (("rev",), ("revolution", "turn"), 2 * math.pi, {}, (), (), True),
    (("rpm",), (), 2 * math.pi / 60, {_T: -1}, (), (), False),
    (("%",), ("percent",), 0.01, {}, (), (), False),
    (("\u2030",), ("permille",), 0.001, {}, (), (), False),
)


def _build_table() -> dict[str, tuple[float, dict[str, int]]]:
    """Every accepted spelling -> (SI factor, dimensions); refuses a spelling defined twice."""
    table: dict[str, tuple[float, dict[str, int]]] = {}

    def add(name: str, factor: float, dims: dict[str, int]) -> None:
        # "mm" must not be both milli-metre and something else: a clash is a table bug.
        if name in table:
            raise AssertionError(f"unit spelling {name!r} defined twice")
        table[name] = (factor, dims)

    for symbols, names, factor, dims, prefixes, long_prefixes, plural in _BASE_UNITS:
        for sym in symbols:
            add(sym, factor, dims)
            for p in prefixes:
                add(p + sym, _SI_PREFIXES[p] * factor, dims)
        for name in names:
            spellings = [(name, factor)] + [
                (p + name, _LONG_PREFIXES[p] * factor) for p in long_prefixes
            ]
            for spelling, f in spellings:
                add(spelling, f, dims)
                if plural:
                    add(spelling + "s", f, dims)
    return table


_UNITS = _build_table()


# --- tokens ----------------------------------------------------------------------------------
_NUMBER = re.compile(
    r"([+-]?)((?:[0-9](?:_?[0-9])*(?:\.(?:[0-9](?:_?[0-9])*)?)?|\.[0-9](?:_?[0-9])*))"
    r"(?:[eE]([+-]?[0-9]+))?"
)
_SUPERSCRIPTS = str.maketrans(
    "\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079\u207b\u207a", "0123456789-+"
)
_TOKEN = re.compile(
    r"(?P<space>[ \t\u00a0\u202f]+)"
    r"|(?P<pow>\*\*|\^)"
    r"|(?P<mul>[*\u00b7\u22c5])"
    r"|(?P<div>/)"
    r"|(?P<open>\()"
    r"|(?P<close>\))"
    r"|(?P<sup>[\u207a\u207b]?[\u2070\u00b9\u00b2\u00b3\u2074-\u2079]+)"
    r"|(?P<int>[+\-\u2212]?[0-9]+(?:\.[0-9]*)?)"
    r"|(?P<name>[A-Za-z_\u00b5\u03bc\u00b0][A-Za-z0-9_\u00b5\u03bc]*|%|\u2030)"
)
# What may be handed to pint: a plain identifier, never an operator, number or bracket.
_IDENTIFIER = re.compile(r"[A-Za-z_\u00b5\u03bc][A-Za-z0-9_\u00b5\u03bc]*")


def _tokens(text: str, pos: int) -> list[tuple[str, str, int]]:
    """Split ``text[pos:]`` into ``(kind, text, position)`` tokens, dropping spaces.

    A space needs no token of its own: two operands in a row multiply, with or without one.
    """
    out = []
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            ch = text[pos]
            hint = " (use a decimal point, no thousands separators)" if ch == "," else ""
            raise _Unreadable(f"unexpected character {ch!r} at position {pos + 1}{hint}")
        if m.lastgroup != "space":
            out.append((m.lastgroup, m.group(), pos))
        pos = m.end()
    return out


# --- dimensions ------------------------------------------------------------------------------
def _combine(a: dict, b: dict, sign: int) -> dict:
    """Dimensions of a*b (sign +1) or a/b (sign -1), zero exponents dropped."""
    out = dict(a)
    for k, v in b.items():
        e = out.get(k, 0) + sign * v
        if e:
            out[k] = e
        else:
            out.pop(k, None)
    return out


def _format_dims(dims: dict) -> str:
    """Pint's spelling of a dimensionality: ``"[length] * [mass] / [time] ** 2"``."""

    def term(k: str, e: float) -> str:
        e = abs(e)
        return k if e == 1 else f"{k} ** {int(e) if float(e).is_integer() else e}"

    num = [term(k, e) for k, e in sorted(dims.items()) if e > 0]
    den = [term(k, e) for k, e in sorted(dims.items()) if e < 0]
    if not num and not den:
        return "dimensionless"
    return " / ".join([" * ".join(num) or "1", *den])


# --- units not in the table ------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _registry():
    import pint

    return pint.UnitRegistry(autoconvert_offset_to_baseunit=True)


@functools.lru_cache(maxsize=256)
def _pint_unit(name: str) -> tuple[float, tuple[tuple[str, float], ...]]:
    """SI factor and dimensions of one unit name pint knows and the table does not.

    Parameters
    ----------
    name : str
        A single identifier (checked again here): pint never sees an expression.

    Returns
    -------
    tuple
        ``(factor, ((dimension, exponent), ...))``; a tuple so the result can be cached.

    Raises
    ------
    _Unreadable
        If pint does not know the name, or it is an offset (degC) or logarithmic (dB) unit,
        whose value is not a factor times the SI unit.
    """
    if not _IDENTIFIER.fullmatch(name):
        raise _Unreadable(f"unknown unit {name!r}")
    ureg = _registry()  # outside the try: a broken pint install should fail loudly
    try:
        q = ureg.Quantity(1, name)
        if not q._is_multiplicative:
            raise _Unreadable(f"{name!r} is an offset or logarithmic unit, not supported here")
        base = q.to_base_units()
        factor = float(base.magnitude)
        dims = tuple((str(k), float(v)) for k, v in base.dimensionality.items() if v)
    except _Unreadable:
        raise
    except Exception:  # UndefinedUnitError, or whatever pint makes of an odd name
        raise _Unreadable(f"unknown unit {name!r}") from None
    if not math.isfinite(factor) or factor == 0:
        raise _Unreadable(f"unknown unit {name!r}")
    return factor, dims


def _unit(name: str) -> tuple[float, dict]:
    """SI factor and dimensions of a unit name: the table first, pint for anything else."""
    hit = _UNITS.get(name)
    if hit is not None:
        return hit
    # pint reads "°C" as "degreeC"; do the same before handing the name over.
    factor, dims = _pint_unit(name.replace("\u00b0", "degree"))
    return factor, {k: int(v) if v.is_integer() else v for k, v in dims}


# --- the parser ------------------------------------------------------------------------------
def _exponent(tokens: list, i: int) -> tuple[int, int]:
    """Read the exponent after a ``^``/``**`` at ``tokens[i]``: ``(value, index after it)``."""
    if i < len(tokens) and tokens[i][0] == "open":
        inner = tokens[i + 1 : i + 3]
        if len(inner) == 2 and inner[0][0] == "int" and inner[1][0] == "close":
            return _small_int(inner[0][1]), i + 3
        raise _Unreadable("an exponent in parentheses must be a whole number, as in 'm^(-1)'")
    if i < len(tokens) and tokens[i][0] == "int":
        return _small_int(tokens[i][1]), i + 1
    raise _Unreadable("'^' or '**' must be followed by a whole number, as in 'm^2'")


def _small_int(text: str) -> int:
    """A whole exponent of at most :data:`_MAX_EXPONENT` in magnitude."""
    if "." in text:
        raise _Unreadable(f"exponent {text!r} is not a whole number")
    text = text.replace("\u2212", "-")  # a typographic minus, as in "s^(−1)"
    digits = text.lstrip("+-")
    if len(digits) > 2 or int(digits) > _MAX_EXPONENT:
        raise _Unreadable(f"exponent {text!r} is out of range: at most {_MAX_EXPONENT}")
    return int(text)


class _UnitFolder:
    """Folds unit tokens left to right into ``(SI factor, dimensions)``: one pass with an
    explicit one-level group, so nothing here recurses or loops more than a fixed number
    of times per token."""

    def __init__(self):
        self.acc_f, self.acc_d = 1.0, {}  # everything folded so far (the number is outside)
        self.op = "*"  # how the pending operand joins acc
        self.pend = None  # the latest operand, not yet folded: [factor, dims, may take a power]
        self.after_operand = True  # the number is an operand: "5 /s" and "5*m" read fine
        self.group = None  # (acc_f, acc_d, op) saved at "("; one level only

    def fold(self) -> None:
        if self.pend is not None:
            f, d, _ = self.pend
            sign = 1 if self.op == "*" else -1
            self.acc_f = self.acc_f * f if sign == 1 else self.acc_f / f
            self.acc_d = _combine(self.acc_d, d, sign)
            self.pend = None

    def power(self, n: int | None) -> None:
        """Raise the pending operand to ``n`` (None: only check that there is one)."""
        if self.pend is None or not self.pend[2]:
            raise _Unreadable("an exponent must follow a unit name or a parenthesis, as in 'm^2'")
        if n is None:
            return
        self.pend[0] = self.pend[0] ** n
        self.pend[1] = {k: v * n for k, v in self.pend[1].items() if v * n}
        self.pend[2] = False  # "m^2^2" is refused: pint reads it right to left, people may not

    def operator(self, kind: str, tok: str, pos: int) -> None:
        if not self.after_operand:
            raise _Unreadable(f"{tok!r} at position {pos + 1} must follow a unit")
        self.fold()
        self.op, self.after_operand = ("*" if kind == "mul" else "/"), False

    def _juxtapose(self) -> None:
        if self.after_operand:  # juxtaposition: "N m" is N*m
            self.fold()
            self.op = "*"

    def operand(self, pend: list) -> None:
        self._juxtapose()
        self.pend = pend
        self.after_operand = True

    def open(self) -> None:
        self._juxtapose()
        if self.group is not None:
            raise _Unreadable("parentheses cannot be nested; write e.g. 'kg/(m*s)'")
        self.group = (self.acc_f, self.acc_d, self.op)
        self.acc_f, self.acc_d, self.op, self.pend = 1.0, {}, "*", None
        self.after_operand = False

    def close(self, pos: int) -> None:
        if self.group is None:
            raise _Unreadable(f"')' at position {pos + 1} closes nothing")
        if not self.after_operand:
            raise _Unreadable(f"nothing before ')' at position {pos + 1}")
        self.fold()
        g_f, g_d = self.acc_f, self.acc_d
        self.acc_f, self.acc_d, self.op = self.group
        self.group = None
        self.pend = [g_f, g_d, True]

    def result(self) -> tuple[float, dict]:
        if self.group is not None:
            raise _Unreadable("'(' is never closed")
        if not self.after_operand:
            raise _Unreadable("it ends with an operator")
        self.fold()
        return self.acc_f, self.acc_d


def _parse_units(tokens: list) -> tuple[float, dict]:
    """Fold the unit tokens left to right into ``(SI factor, dimensions)``."""
    u = _UnitFolder()
    i = 0
    while i < len(tokens):
        kind, tok, pos = tokens[i]
        i += 1
        if kind == "name" and tok == "per":
            kind, tok = "div", "/"
        if kind in ("mul", "div"):
            u.operator(kind, tok, pos)
        elif kind == "name":
            u.operand([*_unit(tok), True])
        elif kind == "int":
            # "1/min", "5 1/s": a literal 1 is accepted only as a numerator
            if tok != "1" or i >= len(tokens) or tokens[i][0] != "div":
                raise _Unreadable(
                    f"unexpected number {tok!r} at position {pos + 1}; "
                    "only one number, at the start, is allowed"
                )
            u.operand([1.0, {}, False])
        elif kind == "open":
            u.open()
        elif kind == "close":
            u.close(pos)
        elif kind == "pow":
            u.power(None)  # check there is something to raise before reading the exponent
            n, i = _exponent(tokens, i)
            u.power(n)
        elif kind == "sup":
            u.power(_small_int(tok.translate(_SUPERSCRIPTS)))
        else:  # pragma: no cover - every token kind is handled above
            raise _Unreadable(f"unexpected {tok!r} at position {pos + 1}")
    return u.result()


def _parse_text(text: str) -> tuple[float, dict]:
    """Read a quantity string: ``(value in SI units, dimensions)``.

    Parameters
    ----------
    text : str
        A stripped string such as ``"300 m/min"``, at most :data:`MAX_CHARS` long.

    Returns
    -------
    tuple of (float, dict)
        The value in SI units (angles in rad) and its dimensions as
        ``{"[length]": 1, "[time]": -1}``.

    Raises
    ------
    _Unreadable
        With the reason, when the string does not follow the grammar of this module.
    """
    m = _NUMBER.match(text)
    if m is None:
        raise _Unreadable("it must start with a number")
    _, mantissa, power10 = m.groups()
    if len(mantissa) > _MAX_MANTISSA:
        raise _Unreadable(f"the number has more than {_MAX_MANTISSA} digits")
    if power10 is not None and len(power10.lstrip("+-")) > _MAX_POWER_OF_TEN:
        raise _Unreadable(f"the power of ten has more than {_MAX_POWER_OF_TEN} digits")
    number = float(m.group())  # the regex only admits what float() reads
    try:
        factor, dims = _parse_units(_tokens(text, m.end()))
    except (OverflowError, ZeroDivisionError):  # a huge unit^4, or one that underflows to 0
        raise _Unreadable("the value is out of range") from None
    return number * factor, dims


@functools.cache
def _expected_dims(dimension: str) -> dict:
    """Dimensions of a :data:`DIMENSIONS` entry, read from its SI unit by this parser."""
    si_unit = DIMENSIONS[dimension][1]
    return {} if si_unit == "1" else _parse_text("1 " + si_unit)[1]


def _shown(text: str) -> str:
    """``text`` for an error message, cut short if it is long."""
    return text if len(text) <= 60 else f"{text[:40]}... ({len(text)} characters)"


def parse_quantity(value: object, dimension: str) -> float:
    """Convert a YAML value to an SI float.

    Parameters
    ----------
    value : float, int or str
        A bare number (taken as SI) or a string with units such as ``"50 um"``; the string
        grammar is described in the module docstring.
    dimension : str
        One of the keys of :data:`DIMENSIONS`.

    Returns
    -------
    float
        The value in SI units (angles in rad, angular speeds in rad/s).

    Raises
    ------
    QuantityError
        If the string cannot be parsed, has the wrong dimension, or is not finite.
    """
    _, si_unit, example = DIMENSIONS[dimension]
    if isinstance(value, bool):
        raise QuantityError(f"expected a {dimension.replace('_', ' ')}, got a boolean")
    if isinstance(value, (int, float)):
        out = float(value)
    elif isinstance(value, str):
        text = value.strip()
        if len(text) > MAX_CHARS:
            raise QuantityError(
                f"cannot read {_shown(text)!r} as a quantity (longer than {MAX_CHARS} "
                f"characters); write e.g. '{example}'"
            )
        try:
            out = float(text)  # "1e3", "0.5": bare numbers are SI
        except ValueError:
            out = _parse_string(text, dimension, example)
    else:
        raise QuantityError(
            f"expected a {dimension.replace('_', ' ')} as a number in {si_unit} or a string "
            f"such as '{example}', got {type(value).__name__}"
        )
    if not math.isfinite(out):
        raise QuantityError(f"{value!r} is not a finite number")
    return out


def _parse_string(text: str, dimension: str, example: str) -> float:
    """Value of a quantity string in SI units, after checking its dimension."""
    try:
        out, dims = _parse_text(text)
    except _Unreadable as exc:
        raise QuantityError(
            f"cannot read {_shown(text)!r} as a quantity ({exc}); write e.g. '{example}'"
        ) from None
    if dims != _expected_dims(dimension):
        raise QuantityError(
            f"{text!r} has dimension {_format_dims(dims)}, expected a "
            f"{dimension.replace('_', ' ')} (e.g. '{example}')"
        )
    return out


def parse_any(text: str) -> tuple[float, dict]:
    """Read a quantity string of any dimension: ``(value in SI units, dimensions)``, the
    dimensions as ``{"[length]": 1, "[time]": -1}`` (empty for a plain number).

    Raises
    ------
    QuantityError
        If the string does not follow the grammar of this module or is not finite.
    """
    text = text.strip()
    if len(text) > MAX_CHARS:
        raise QuantityError(
            f"cannot read {_shown(text)!r} as a quantity (longer than {MAX_CHARS} characters)"
        )
    try:
        out, dims = _parse_text(text)
    except _Unreadable as exc:
        raise QuantityError(f"cannot read {_shown(text)!r} as a quantity ({exc})") from None
    if not math.isfinite(out):
        raise QuantityError(f"{text!r} is not a finite number")
    return out, dims
