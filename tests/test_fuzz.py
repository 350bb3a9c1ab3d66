"""Fuzzing the input files: seeded mutations of the shipped line and scenario files, read by
`r2rsim validate` and run by `r2rsim run` (in process, through the CLI entry point).

Every mutation must end without a traceback and within a time limit. A mutation that makes
the input certainly invalid (a number turned into nan, inf, a boolean or a hostile string;
an unknown or a duplicated key; bytes that are not UTF-8) must exit 2 with `error:` lines on
stderr naming the file, and write nothing. Any run that exits 2 writes nothing; one that
exits 1 keeps its dataset, marked. The counts are printed (``pytest -s``) for the record.
"""

from __future__ import annotations

import contextlib
import io
import math
import random
import signal
from pathlib import Path

import pytest
import yaml

from r2rsim.cli import main

REPO = Path(__file__).resolve().parents[1]
SEED = 20261124
N_MUTATIONS = 100
RUN_EVERY = 4  # every 4th mutation is also run (--duration 0.2 s)
TIME_LIMIT_S = 30  # per command; the slowest legitimate one takes a few seconds

HOSTILE_NUMBERS = [
    math.nan,
    math.inf,
    -math.inf,
    True,
    False,
    "10**10**10 m",
    "1/0 m",
    "5 m/0",
    "(5 m",
    "2**1000000 m",
    "9" * 400 + " m",
    "1 " + "m " * 3000,
    "banana",
    "",
    "\x00",
    "1e999999",
    [],
    {},
    [[[[[1]]]]],
]
HOSTILE_STRINGS = [
    "",
    "\x00",
    "../../escape",
    "x/../../../pwned",
    "a" * 10000,
    "é\u202e",
    42,
    None,
    [],
    {"a": 1},
]
NEUTRAL_NUMBERS = [0, -1, 1e300, -1e300, 1e-300, 7]


class Hang(Exception):
    pass


@contextlib.contextmanager
def time_limit(seconds: int):
    def on_alarm(signum, frame):
        raise Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _leaves(node, path=()):
    """(path, value) of every scalar in a parsed YAML tree."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaves(v, (*path, i))
    else:
        yield path, node


def _mappings(node, path=()):
    if isinstance(node, dict):
        yield path, node
        for k, v in node.items():
            yield from _mappings(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _mappings(v, (*path, i))


def _set(tree, path, value):
    node = tree
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


def mutate(rng: random.Random, text: str) -> tuple[str | bytes, str, bool]:
    """One mutation of a YAML text: (new text or bytes, what was done, certainly invalid)."""
    tree = yaml.safe_load(text)
    kind = rng.choice(
        [
            "number",
            "number",
            "string",
            "neutral",
            "drop",
            "unknown",
            "duplicate",
            "truncate",
            "bytes",
        ]
    )
    leaves = list(_leaves(tree))
    numbers = [
        (p, v) for p, v in leaves if isinstance(v, (int, float)) and not isinstance(v, bool) and p
    ]
    strings = [(p, v) for p, v in leaves if isinstance(v, str) and p]
    if kind == "number" and numbers:
        path, _ = rng.choice(numbers)
        value = rng.choice(HOSTILE_NUMBERS)
        _set(tree, path, value)
        # a bare number in a list of numbers (a table or polynomial) is still a number
        # there, but never nan, inf, a boolean or any of these strings
        return yaml.safe_dump(tree), f"{'.'.join(map(str, path))} = {value!r:.40}", True
    if kind == "string" and strings:
        path, _ = rng.choice(strings)
        value = rng.choice(HOSTILE_STRINGS)
        _set(tree, path, value)
        return yaml.safe_dump(tree), f"{'.'.join(map(str, path))} = {value!r:.40}", False
    if kind == "neutral" and numbers:
        path, _ = rng.choice(numbers)
        value = rng.choice(NEUTRAL_NUMBERS)
        _set(tree, path, value)
        return yaml.safe_dump(tree), f"{'.'.join(map(str, path))} = {value!r}", False
    if kind == "drop":
        maps = [(p, m) for p, m in _mappings(tree) if m]
        path, m = rng.choice(maps)
        key = rng.choice(list(m))
        del m[key]
        return yaml.safe_dump(tree), f"drop {'.'.join(map(str, (*path, key)))}", False
    if kind == "unknown":
        maps = [(p, m) for p, m in _mappings(tree)]
        path, m = rng.choice(maps)
        m["zz_not_a_key"] = 1.0
        return yaml.safe_dump(tree), f"unknown key in {'.'.join(map(str, path)) or 'top'}", True
    if kind == "duplicate":
        first = next(line for line in text.splitlines() if line and line[0].isalpha())
        return text + "\n" + first + "\n", f"duplicate {first.split(':')[0]!r}", True
    if kind == "truncate":
        cut = rng.randrange(0, len(text))
        return text[:cut], f"truncated at {cut}", False
    raw = bytearray(text.encode())
    at = rng.randrange(0, len(raw))
    raw[at:at] = bytes([0xFF, 0xFE, 0xC3])
    return bytes(raw), f"invalid UTF-8 at byte {at}", True


def _call(argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse
            rc = exc.code
    return rc, out.getvalue(), err.getvalue()


def _pairs():
    """(scenario file, its line file) of every shipped scenario (not the sweep files kept
    beside them: their base scenarios are among these)."""
    for scen in sorted((REPO / "scenarios").rglob("*.yaml")):
        d = yaml.safe_load(scen.read_text(encoding="utf-8"))
        if "line" in d:
            yield scen, (scen.parent / d["line"]).resolve()


def test_fuzz_shipped_files(tmp_path):
    rng = random.Random(SEED)
    pairs = list(_pairs())
    counts = {"cases": 0, "invalid": 0, "exit0": 0, "exit1": 0, "exit2": 0, "runs": 0}
    failures = []
    for i in range(N_MUTATIONS):
        scen, line = rng.choice(pairs)
        case = tmp_path / f"c{i:03d}"
        case.mkdir()
        target = rng.choice(["scenario", "line"])
        s_text = scen.read_text(encoding="utf-8")
        l_text = line.read_text(encoding="utf-8")
        d = yaml.safe_load(s_text)
        d["line"] = "line.yaml"
        s_text = yaml.safe_dump(d)
        text = s_text if target == "scenario" else l_text
        new, what, invalid = mutate(rng, text)
        s_path, l_path = case / "scenario.yaml", case / "line.yaml"
        if target == "scenario":
            (s_path.write_bytes if isinstance(new, bytes) else s_path.write_text)(new)
            l_path.write_text(l_text)
        else:
            s_path.write_text(s_text)
            (l_path.write_bytes if isinstance(new, bytes) else l_path.write_text)(new)
        label = f"#{i} {scen.name} {target}: {what}"
        counts["cases"] += 1
        counts["invalid"] += invalid
        commands = [["validate", str(s_path)]]
        if i % RUN_EVERY == 0 or invalid:
            commands.append(
                ["run", str(s_path), "-o", str(case / "out"), "-q", "--duration", "0.2"]
            )
        for argv in commands:
            try:
                with time_limit(TIME_LIMIT_S):
                    rc, out, err = _call(argv)
            except Hang as exc:
                failures.append(f"{label}: r2rsim {argv[0]} hangs ({exc})")
                continue
            except Exception as exc:  # noqa: BLE001 - a traceback is what we look for
                failures.append(
                    f"{label}: r2rsim {argv[0]} raised {exc.__class__.__name__}: {str(exc)[:200]}"
                )
                continue
            if rc in (0, 1, 2):
                counts[f"exit{rc}"] += 1
            if argv[0] == "run":
                counts["runs"] += 1
            leftovers = [p.name for p in case.iterdir() if p.name.startswith((".out", "out"))]
            if invalid and rc != 2:
                failures.append(f"{label}: r2rsim {argv[0]} exit {rc} on invalid input")
            if rc == 2:
                lines = [ln for ln in err.splitlines() if ln.strip()]
                # (an unknown key's message quotes its line of the file, indented)
                if (
                    not lines
                    or not all(
                        ln.startswith(("error:", str(case), "warning:", "    ")) for ln in lines
                    )
                    or lines[0].startswith(" ")
                ):
                    failures.append(
                        f"{label}: r2rsim {argv[0]} exit 2 without a clean message: {err[:300]!r}"
                    )
                elif str(case) not in err:
                    failures.append(
                        f"{label}: r2rsim {argv[0]} message names no file: {err[:300]!r}"
                    )
                if leftovers:
                    failures.append(f"{label}: r2rsim {argv[0]} exit 2 left {leftovers}")
            elif rc not in (0, 1):
                failures.append(f"{label}: r2rsim {argv[0]} exit {rc}: {err[:300]!r}")
            if argv[0] == "run" and rc in (0, 1) and [p for p in leftovers if p != "out"]:
                failures.append(f"{label}: temporary directories left: {leftovers}")
    print(counts)
    assert counts["invalid"] >= 25  # the mix really exercises the certainly-invalid cases
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("seed", [1, 2])
def test_mutations_are_seeded(seed):
    text = (REPO / "lines" / "pet_film_line.yaml").read_text(encoding="utf-8")
    a = [mutate(random.Random(seed), text)[1] for _ in range(3)]
    b = [mutate(random.Random(seed), text)[1] for _ in range(3)]
    assert a == b
