"""Independent references the tests compare the engine with, written from the model's
matrices alone (never through the engine's own integrators)."""

import numpy as np

from campipe.engine.batch import train_matrices


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


def recorded_digests(path) -> dict[str, str]:
    """The digests a file records, digest → the platform it was computed on: one line each,
    ``<digest> <platform>`` (a bare digest: the platform it was first recorded on, not named)."""
    out = {}
    for line in path.read_text().splitlines():
        if line.strip():
            digest, *platform = line.split()
            out[digest] = " ".join(platform) or "not named"
    return out


def record_digest(path, digest: str) -> None:
    """Record ``digest`` as this platform's (``CAMPIPE_UPDATE_DIGEST=1``): it replaces every
    digest recorded before, which a change of results leaves stale; another platform records
    its own by running the test there with the same variable."""
    path.write_text(f"{digest} {numerical_platform()}\n")


def add_platform_digest(path, digest: str) -> None:
    """Add ``digest`` as this platform's beside the others (``CAMPIPE_ADD_PLATFORM_DIGEST=1``),
    for a platform whose LAPACK rounds differently, the code unchanged."""
    kept = {d: p for d, p in recorded_digests(path).items() if p != numerical_platform()}
    kept[digest] = numerical_platform()
    path.write_text("".join(f"{d} {p}\n" for d, p in kept.items()))
