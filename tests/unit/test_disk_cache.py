"""What a process keeps for the next (``campipe.disk_cache``): the quantity texts' SI values
(``campipe.units``) read back bit for bit, under their own key only, never from a damaged file,
and nothing kept (silently) where the folder cannot be written."""

import json
import os
import random
import struct
import time

import numpy as np
import pytest

from campipe import disk_cache, kernel_cache, units
from campipe.units import QuantityError, parse_angular, parse_quantity

#: Texts and units whose SI values are inexact binary fractions, one negative zero among them.
QUANTITIES = [
    ("0.1 in", "m"),
    ("245 lbf/in", "N/m"),
    ("0.283 lbf/in**3", "N/m**3"),
    ("-0 in", "m"),
    ("30e6 lbf/in**2", "Pa"),
]
ANGULAR = [("9524 rpm", "rad/s"), ("268 deg", "rad")]
#: What the values above keep: each units' factor and offset (``units._by_factor``), read
#: once for "0.1 in" and "-0 in" alike.
KEPT = {
    (kind, f"{n} {text.split(' ', 1)[1]}", to)
    for kind, texts in (("quantity", QUANTITIES), ("angular", ANGULAR))
    for text, to in texts
    for n in (0, 1)
}


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A kernel cache of its own (this source's folder under ``tmp_path``), and units'
    values as a fresh process finds them: none read yet."""
    source = tmp_path / "0123456789abcdef"
    monkeypatch.setattr(kernel_cache, "cache_root", lambda: tmp_path)
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: source)
    fresh_process(monkeypatch)
    return source


def fresh_process(monkeypatch) -> None:
    monkeypatch.setattr(units, "_known", None)
    monkeypatch.setattr(units, "_found", {})
    units._parse_text.cache_clear()


def values() -> list[float]:
    return [parse_quantity(t, u, "k") for t, u in QUANTITIES] + [
        parse_angular(t, u, "k", "rpm") for t, u in ANGULAR
    ]


def bits(xs: list[float]) -> list[bytes]:
    return [struct.pack("<d", x) for x in xs]


def no_pint(monkeypatch) -> None:
    def refuse():
        raise AssertionError("pint consulted")

    monkeypatch.setattr(units, "_pint", refuse)
    monkeypatch.setattr(units, "registry", refuse)


def test_kept_values_are_read_back_bit_for_bit_without_pint(folder, monkeypatch):
    """A later process reads every value the first found, bit for bit (-0.0 included),
    without pint."""
    first = values()
    assert struct.pack("<d", first[3]) == struct.pack("<d", -0.0)
    units._keep_found()
    assert len(list((folder / "quantities").iterdir())) == 1
    fresh_process(monkeypatch)
    no_pint(monkeypatch)
    assert bits(values()) == bits(first)


def test_conversions_are_kept_by_type_and_value(folder, monkeypatch):
    rpm = units.convert(1.0, "rad/s", "rpm")
    units._keep_found()
    fresh_process(monkeypatch)
    no_pint(monkeypatch)
    assert struct.pack("<d", units.convert(1.0, "rad/s", "rpm")) == struct.pack("<d", rpm)
    with pytest.raises(AssertionError, match="pint consulted"):
        units.convert(1, "rad/s", "rpm")  # an int is another argument


def test_another_pint_or_units_source_misses(folder, monkeypatch):
    """The values are kept under pint's version and this units module's source: another of
    either reads none of them (and keeps its own beside them)."""
    values()
    units._keep_found()
    key = units._store_key()
    assert key is not None and "pint " in key
    for other in (key.replace("pint ", "pint 0.0-other "), key[:-1] + chr(ord(key[-1]) ^ 1)):
        with monkeypatch.context() as m:
            m.setattr(units, "_store_key", lambda other=other: other)
            assert units._read_kept() == {}
    assert {tuple(json.loads(k)) for k in units._read_kept()} == KEPT


@pytest.mark.parametrize(
    "damage",
    [
        lambda data: data[:-3],  # cut short
        lambda data: data[:-5] + bytes([data[-5] ^ 1]) + data[-4:],  # one bit flipped
        lambda data: b"",
        lambda data: b"\x00" * len(data),
    ],
    ids=["truncated", "bit-flip", "empty", "zeros"],
)
def test_a_damaged_file_is_passed_over_and_the_values_computed(folder, monkeypatch, damage):
    first = values()
    units._keep_found()
    (path,) = (folder / "quantities").iterdir()
    path.write_bytes(damage(path.read_bytes()))
    assert disk_cache.read("quantities", units._store_key()) is None
    fresh_process(monkeypatch)
    assert bits(values()) == bits(first)  # computed by pint again
    assert {tuple(json.loads(k)) for k in units._found} == KEPT


def test_a_file_of_another_key_is_not_read_as_this_ones(folder):
    disk_cache.write("quantities", "a", b"{}")
    (path,) = (folder / "quantities").iterdir()
    path.rename(path.with_name(disk_cache._digest("quantities", "b")[:32]))
    assert disk_cache.read("quantities", "b") is None
    disk_cache.write("quantities", "b", b"[1]")
    assert disk_cache.read("quantities", "b") == b"[1]"


def test_a_refusal_is_never_kept(folder):
    with pytest.raises(QuantityError):
        parse_quantity("9 furlong/fortnight", "N", "k")
    with pytest.raises(QuantityError):
        parse_angular("9 Hz", "rad/s", "k", "rpm")
    assert units._found == {}


def test_an_unwritable_folder_keeps_nothing_silently(tmp_path, monkeypatch):
    """A cache folder that cannot be made (a file stands in its way): nothing kept, nothing
    raised, and the values still found."""
    blocked = tmp_path / "file"
    blocked.write_text("")
    monkeypatch.setattr(kernel_cache, "cache_root", lambda: blocked)
    monkeypatch.setattr(kernel_cache, "cache_folder", lambda: blocked / "0123456789abcdef")
    fresh_process(monkeypatch)
    first = values()
    units._keep_found()
    assert disk_cache.read("quantities", units._store_key()) is None
    fresh_process(monkeypatch)
    assert bits(values()) == bits(first)


def test_each_kind_keeps_the_files_written_last(folder):
    n = disk_cache.KEEP + 3
    then = time.time() - 1000
    for i in range(n):
        disk_cache.write("quantities", f"key {i}", b"{}")
        path = folder / "quantities" / disk_cache._digest("quantities", f"key {i}")[:32]
        os.utime(path, (then + i, then + i))  # written in this order
    kept = [disk_cache.read("quantities", f"key {i}") is not None for i in range(n)]
    assert kept == [False] * (n - disk_cache.KEEP) + [True] * disk_cache.KEEP


#: Units a range may be written in, and the SI units read, by kind.
RANGE_UNITS = [
    ("quantity", "in", "m"),
    ("quantity", "mm", "m"),
    ("quantity", "lbf/in", "N/m"),
    ("quantity", "lbf*s/in", "N*s/m"),
    ("quantity", "lb*in**2", "kg*m**2"),
    ("quantity", "psi", "Pa"),
    ("angular", "rpm", "rad/s"),
    ("angular", "deg", "rad"),
    ("angular", "revolution/min", "rad/s"),
]


def test_a_ranges_values_are_read_as_pint_reads_them_bit_for_bit_keeping_only_factors(folder):
    """Each value of a range is its number times its units' factor (``units._by_factor``):
    the same float, bit for bit, as pint converting the text itself (``units._parse``,
    ``units._angular``, uncached), over numbers as ranges write them (whole, decimal, tiny,
    huge, negative); and only each units' factor and offset are kept, not the values."""
    rng = random.Random(7)
    numbers = [0.0, -0.0, 6000.0, 6000.5, 1e-9, 3.7e12, -12.25]
    numbers += [rng.uniform(-2e4, 2e4) for _ in range(300)]
    numbers += [round(rng.uniform(0, 2e4), 3) for _ in range(300)]
    numbers += [10 ** rng.uniform(-8, 8) for _ in range(300)]
    for kind, unit, to in RANGE_UNITS:
        for x in numbers:
            text = f"{x!r} {unit}"
            if kind == "angular":
                got, pint_reads = (
                    parse_angular(text, to, "k", "rpm"),
                    units._angular(text, to, "k", "rpm"),
                )
            else:
                got, pint_reads = parse_quantity(text, to, "k"), units._parse(text, to, "k", None)
            assert struct.pack("<d", got) == struct.pack("<d", pint_reads), text
    kept = {tuple(json.loads(k)) for k in units._found}
    assert kept == {(kind, f"{n} {unit}", to) for kind, unit, to in RANGE_UNITS for n in (0, 1)}


def test_units_with_an_offset_and_refused_texts_are_read_by_pint_whole(folder):
    """degC's zero is not 0 K: its text is converted by pint whole; a refusal names the text
    as written, not the units' factor."""
    assert parse_quantity("20 degC", "K", "k") == units._parse("20 degC", "K", "k", None)
    assert ("quantity", "20 degC", "K") in {tuple(json.loads(k)) for k in units._found}
    with pytest.raises(QuantityError, match="'9000 Hz'"):
        parse_angular("9000 Hz", "rad/s", "k", "rpm")
    with pytest.raises(QuantityError, match="'1e305 lbf/in\\*\\*4'.*beyond the range"):
        parse_quantity("1e305 lbf/in**4", "N/m**4", "k")


def _arrays_kept(monkeypatch) -> None:
    """A process that has written no arrays yet."""
    monkeypatch.setattr(disk_cache, "_written", {})


def test_arrays_are_read_back_bit_for_bit_in_the_order_they_were_computed(folder, monkeypatch):
    """``disk_cache.arrays``: what ``compute`` gave is read back bit for bit (a negative zero,
    a NaN's payload, complex and integer arrays), contiguous in the order it was computed in
    (Fortran stays Fortran; a strided view is made C-contiguous, computed or read alike),
    without calling ``compute``."""
    _arrays_kept(monkeypatch)
    rng = np.random.default_rng(7)
    x = rng.normal(size=(5, 4))
    x[0, 0], x[1, 1] = -0.0, np.frombuffer(struct.pack("<Q", 0x7FF8DEADBEEF0001), "<f8")[0]
    made = [
        np.asfortranarray(x),
        x[::2, 1:3],
        rng.normal(size=3) + 1j * rng.normal(size=3),
        np.arange(6, dtype=np.int32),
    ]
    calls = []

    def compute():
        calls.append(1)
        return made

    first = disk_cache.arrays("test", [x], "v1", compute)
    again = disk_cache.arrays("test", [x], "v1", compute)
    assert len(calls) == 1
    for a, b, m in zip(first, again, made, strict=True):
        assert a.dtype == b.dtype == m.dtype and a.shape == b.shape == m.shape
        assert a.tobytes("A") == b.tobytes("A") and np.array_equal(a, m, equal_nan=True)
        assert a.flags.f_contiguous == b.flags.f_contiguous
        assert a.flags.c_contiguous or a.flags.f_contiguous
        assert b.flags.writeable
    assert first[0].flags.f_contiguous and not first[0].flags.c_contiguous
    assert first[1].flags.c_contiguous


def test_arrays_of_other_inputs_or_versions_are_computed(folder, monkeypatch):
    """A bit of an input changed, the same bytes in another shape or type, or another
    version: computed, never another key's arrays. A damaged file: computed."""
    _arrays_kept(monkeypatch)
    x = np.linspace(0.0, 1.0, 6)
    calls = []

    def compute(tag):
        def run():
            calls.append(tag)
            return [np.full(2, float(len(calls)))]

        return run

    base = disk_cache.arrays("test", [x], "v1", compute("base"))
    flipped = x.copy()
    flipped.view(np.uint64)[3] ^= 1
    for inputs, version, tag in [
        ([flipped], "v1", "bit"),
        ([x.reshape(2, 3)], "v1", "shape"),
        ([x.view(np.int64)], "v1", "type"),
        ([x], "v2", "version"),
        ([x, x], "v1", "more"),
    ]:
        got = disk_cache.arrays("test", inputs, version, compute(tag))
        assert calls[-1] == tag and got[0][0] != base[0][0]
    assert disk_cache.arrays("test", [x], "v1", compute("again"))[0][0] == base[0][0]
    assert calls[-1] != "again"
    for path in (folder / "test").iterdir():
        path.write_bytes(path.read_bytes()[:-3] + b"xyz")
    disk_cache.arrays("test", [x], "v1", compute("damaged"))
    assert calls[-1] == "damaged"


def test_a_process_writes_few_arrays_of_a_kind(folder, monkeypatch):
    """Past ``KEEP`` files of a kind written, a process computes without writing: a study of
    hundreds of trains pays no write for each."""
    _arrays_kept(monkeypatch)
    n = disk_cache.KEEP + 4
    for i in range(n):
        disk_cache.arrays("test", [np.array([float(i)])], "v1", lambda: [np.zeros(1)])
    assert len(list((folder / "test").iterdir())) == disk_cache.KEEP
    assert disk_cache._written["test"] == disk_cache.KEEP


def test_modes_are_read_back_only_on_the_same_kind_of_processor(folder, monkeypatch):
    """A train's modes kept on disk are read back by a process on the same processor; one on
    another model, with other instruction sets, or with OpenBLAS told another core computes
    them itself (LAPACK's last bits differ between OpenBLAS's kernels; a cache on a cluster's
    shared home is read by every node)."""
    from campipe.model import assembly

    _arrays_kept(monkeypatch)
    calls = []
    solve = assembly._normal_modes

    def counted(*args):
        calls.append(1)
        return solve(*args)

    monkeypatch.setattr(assembly, "_normal_modes", counted)
    mass, stiffness = np.diag([1.0, 2.0]), np.array([[3.0, -1.0], [-1.0, 1.0]])
    here = {"model name": "Example CPU", "flags": "fpu sse2 avx2"}
    others = [
        ({"model name": "Example CPU v2", "flags": "fpu sse2 avx2"}, {}),
        ({"model name": "Example CPU", "flags": "fpu sse2 avx2 avx512f"}, {}),
        (here, {"OPENBLAS_CORETYPE": "Prescott"}),
    ]

    def on(info, env):
        monkeypatch.setattr(disk_cache, "cpu_info", lambda: dict(info))
        monkeypatch.delenv("OPENBLAS_CORETYPE", raising=False)
        for name, value in env.items():
            monkeypatch.setenv(name, value)
        disk_cache.processor_kind.cache_clear()
        assembly.lapack_version.cache_clear()
        return assembly.normal_modes(mass, stiffness)

    try:
        first = on(here, {})
        again = on({"flags": "avx2 sse2 fpu", "model name": "Example CPU"}, {})  # flags' order
        assert len(calls) == 1
        assert all(a.tobytes() == b.tobytes() for a, b in zip(first, again, strict=True))
        for n, (info, env) in enumerate(others, start=2):
            on(info, env)
            assert len(calls) == n, (info, env)
    finally:
        disk_cache.processor_kind.cache_clear()
        assembly.lapack_version.cache_clear()
