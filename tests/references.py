"""Independent references the tests compare the engine with, written from the model's
matrices alone (never through the engine's own integrators)."""

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import campipe
from campipe.disk_cache import cpu_info
from campipe.engine.batch import train_matrices

ROOT = Path(__file__).resolve().parents[1]
#: OpenBLAS's kernels whose digests every digest file records: a platform whose own digest is
#: not recorded computes it again on these (:func:`on_reference_kernels`), where the processor
#: runs them (AVX2 and FMA: every x86 processor of the last decade).
REFERENCE_KERNELS = "Haswell"


def steady_state_cam_force(train, speed, lift, theta):
    """Contact force of the harmonic cam in configuration I once transients have decayed: the
    frequency response of the train with q1 prescribed, q1 = −h/2 + (h/2)·sin θ."""
    sm = train_matrices(train)
    M, C, K, f = sm.mass, sm.damping, sm.stiffness, sm.preload
    fr = np.arange(1, 7)
    q1_mean, q1_amp = -lift / 2, -1j * lift / 2  # (h/2) sin θ = Re(−i·h/2·e^{iθ})
    x0 = np.linalg.solve(K[np.ix_(fr, fr)], f[fr] - K[fr, 0] * q1_mean)

    def dyn(rows, cols):
        return (
            K[np.ix_(rows, cols)]
            - speed**2 * M[np.ix_(rows, cols)]
            + 1j * speed * C[np.ix_(rows, cols)]
        )

    x1 = np.linalg.solve(dyn(fr, fr), -dyn(fr, [0])[:, 0] * q1_amp)
    # F1 = row 1 of (K − ω²M + iωC) applied to the complex amplitude, plus the static part.
    static = K[0, fr] @ x0 + K[0, 0] * q1_mean - f[0]
    amp = dyn([0], fr)[0] @ x1 + dyn([0], [0])[0, 0] * q1_amp
    return static + np.real(amp * np.exp(1j * theta))


def numerical_platform() -> str:
    """The BLAS kernels this process's numpy and SciPy run on, as OpenBLAS names them
    ("Haswell", "SkylakeX", …; "unknown" where it cannot be read): LAPACK's results (the
    modes, the modal damping) differ in their last bits between them, and every number after
    with them. A bit-identity digest holds per platform (``recorded_digests``)."""
    import ctypes

    names = []
    try:
        with open("/proc/self/maps") as maps:
            paths = sorted({line.split()[-1] for line in maps if "openblas" in line.lower()})
    except OSError:
        paths = []
    for path in paths:
        lib = ctypes.CDLL(path)
        for symbol in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename",
                       "openblas_get_corename64_", "openblas_get_corename"):  # fmt: skip
            function = getattr(lib, symbol, None)
            if function is not None:
                function.restype = ctypes.c_char_p
                names.append(function().decode())
                break
    return "+".join(sorted(set(names))) or "unknown"


def recorded_digests(path, name: str | None = None) -> dict[str, str]:
    """The digests a file records, digest → the platform it was computed on: one line each,
    ``<digest> <platform>`` (a bare digest: the platform it was first recorded on, not named);
    with ``name``, the lines ``<name> <digest> <platform>`` of that name only."""
    out = {}
    for line in path.read_text().splitlines():
        words = line.split()
        if name is not None:
            if not words or words[0] != name:
                continue
            words = words[1:]
        if words:
            digest, *platform = words
            out[digest] = " ".join(platform) or "not named"
    return out


def record_digest(path, digest: str, source: str, call: str) -> None:
    """Record ``digest`` (``call``'s of the test file ``source``) as this platform's
    (``CAMPIPE_UPDATE_DIGEST=1``), and the same computation's on the reference kernels
    (:func:`on_reference_kernels`) where this platform's are others: they replace every digest
    recorded before, which a change of results leaves stale."""
    recorded = {digest: numerical_platform()}
    again = on_reference_kernels(source, call)
    if again is not None:
        recorded[again] = REFERENCE_KERNELS
    path.write_text("".join(f"{d} {p}\n" for d, p in recorded.items()))


def add_platform_digest(path, digest: str) -> None:
    """Add ``digest`` as this platform's beside the others (``CAMPIPE_ADD_PLATFORM_DIGEST=1``),
    for a platform whose LAPACK rounds differently, the code unchanged."""
    kept = {d: p for d, p in recorded_digests(path).items() if p != numerical_platform()}
    kept[digest] = numerical_platform()
    path.write_text("".join(f"{d} {p}\n" for d, p in kept.items()))


def on_reference_kernels(source: str, call: str) -> str | None:
    """``call`` (a digest: "mixed_digest()") of the test file ``source``, computed in a new
    process on OpenBLAS's :data:`REFERENCE_KERNELS`, which ``OPENBLAS_CORETYPE`` (OpenBLAS's
    own override) selects, with this process's campipe. None where this process already runs
    them or the processor cannot (no AVX2 or FMA)."""
    if numerical_platform() == REFERENCE_KERNELS:
        return None
    if not {"avx2", "fma"} <= set(cpu_info().get("flags", "").split()):
        return None
    path = str(Path(source).resolve())
    code = (
        "import campipe, importlib.util, sys\n"  # this process's campipe, then the tests
        f"sys.path.append({str(ROOT)!r})\n"
        f"spec = importlib.util.spec_from_file_location('source', {path!r})\n"
        "module = importlib.util.module_from_spec(spec)\n"
        "spec.loader.exec_module(module)\n"
        f"print(module.{call})"
    )
    env = {
        **os.environ,
        "OPENBLAS_CORETYPE": REFERENCE_KERNELS,
        "PYTHONPATH": os.pathsep.join(
            [str(Path(campipe.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
        ),
    }
    with tempfile.TemporaryDirectory() as cwd:
        done = subprocess.run(
            [sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True
        )
    assert done.returncode == 0, done
    return done.stdout.split()[-1]


def assert_recorded(digest: str, recorded: dict[str, str], source: str, call: str) -> None:
    """``digest`` (``call``'s of the test file ``source``) is one of ``recorded`` (digest →
    platform). On a platform whose own is not recorded, the same computation on the reference
    kernels (:func:`on_reference_kernels`) must give a recorded one instead: the results did
    not change, only their last bits with this platform's LAPACK."""
    if digest in recorded:
        return
    platform = numerical_platform()
    here = f"the digest {digest} on platform {platform}"
    if platform in recorded.values():
        raise AssertionError(f"{here} is not the one recorded for it: results changed")
    again = on_reference_kernels(source, call)
    if again is None:
        raise AssertionError(
            f"{here} is none of those recorded ({recorded}), and this processor cannot run the "
            f"{REFERENCE_KERNELS} kernels they were recorded on: record this platform's with "
            "CAMPIPE_ADD_PLATFORM_DIGEST=1 on code whose digest holds on a recorded platform"
        )
    assert again in recorded, (
        f"{here} is not recorded, and on the {REFERENCE_KERNELS} kernels it is {again}, none "
        f"of those recorded ({recorded}): results changed"
    )
