"""CasADi functions compiled to C once and cached on disk (the batched MHE's window evaluation).

CasADi evaluates an SX function in its virtual machine, one instruction at a time: the MHE's window function
(outputs and Jacobian over the horizon, about 24,000 instructions for theta alone) takes about 250 us a call
there (200 us per window in a serial map of 8) and about 45 us compiled (20 us per window in a map of 8),
measured on the project machine; ``tests/estimators/test_mhe_batched.py`` checks the two agree.
:func:`compiled` writes the function's C code with CasADi's code generator, compiles it with the system C compiler
(``$CC``, else ``cc``/``gcc``) into ``<cache>/<name>_<sha256 of the source>.so`` and loads it with
``casadi.external``. The same source gives the same file, so a function is compiled once per machine
and later processes load it. The compile is done into a temporary file renamed into place, so parallel processes
never load a half-written library.

:class:`BatchCall` evaluates a function for N instances with ``Function.map`` through CasADi's buffer interface:
numpy arrays in and out, with no conversion through ``DM`` (which, for the MHE's sparse Jacobian, cost more than
the compiled evaluation itself).

Compiler flags: ``-O1`` (3.5 s to compile; ``-O2`` took 6.3 s for a window function about 10 % faster) and
``-ffp-contract=off`` (no fused multiply-adds: the compiled function rounds as the virtual machine does, so the
results agree to the last bit on the tested machine). Without a C compiler, or if compiling fails, :func:`compiled` returns None and the caller
keeps the virtual machine (slower, same results).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["CACHE_ENV", "C_FLAGS", "BatchCall", "cache_dir", "compiled", "densified"]

CACHE_ENV = "FRICENV_CASADI_CACHE"  # environment variable overriding the cache directory
C_FLAGS = ("-O1", "-ffp-contract=off", "-fPIC", "-shared")
COMPILE_TIMEOUT_S = 300.0


def cache_dir() -> Path:
    """The directory of compiled functions: ``$FRICENV_CASADI_CACHE``, else ``~/.cache/fricenv/casadi``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env) if env else Path.home() / ".cache" / "fricenv" / "casadi"


def _compiler() -> str | None:
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _source(fun: ca.Function) -> str:
    """The C source of ``fun`` from CasADi's code generator."""
    with tempfile.TemporaryDirectory() as tmp:
        gen = ca.CodeGenerator(f"{fun.name()}.c")
        gen.add(fun)
        gen.generate(f"{tmp}{os.sep}")  # the prefix is the directory written into
        return (Path(tmp) / f"{fun.name()}.c").read_text()


def compiled(fun: ca.Function, directory: Path | None = None) -> ca.Function | None:
    """``fun`` compiled to C and loaded (from the cache if it is there), or None if no compiler could build it.

    :param fun: an SX (or MX) CasADi function.
    :param directory: cache directory (default :func:`cache_dir`).
    """
    compiler = _compiler()
    if compiler is None:
        return None
    source = _source(fun)
    digest = hashlib.sha256((source + " ".join(C_FLAGS)).encode()).hexdigest()[:16]
    folder = Path(directory) if directory is not None else cache_dir()
    library = folder / f"{fun.name()}_{digest}.so"
    if not library.exists():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=folder) as tmp:
                src, out = Path(tmp) / f"{fun.name()}.c", Path(tmp) / "lib.so"
                src.write_text(source)
                subprocess.run([compiler, *C_FLAGS, str(src), "-o", str(out), "-lm"], check=True,
                               capture_output=True, timeout=COMPILE_TIMEOUT_S)
                os.replace(out, library)
        except (OSError, subprocess.SubprocessError):
            return None
    try:
        return ca.external(fun.name(), str(library))
    except RuntimeError:
        return None


def densified(fun: ca.Function) -> ca.Function:
    """The SX function ``fun`` with every output dense (structural zeros stored), for :class:`BatchCall`."""
    args = fun.sx_in()
    return ca.Function(fun.name(), args, [ca.densify(o) for o in fun.call(args)])


class BatchCall:
    """``fun`` (dense outputs) evaluated for N instances in one mapped call, numpy in and out.

    :param fun: a function whose inputs are vectors and whose outputs are dense.
    :param n: number of instances.
    :param mode: ``"serial"`` or ``"thread"`` (``Function.map``).
    :param threads: threads of the thread map.
    """

    def __init__(self, fun: ca.Function, n: int, mode: str = "serial", threads: int = 1):
        self.n = int(n)
        mapped = fun.map(self.n, "thread", threads) if mode == "thread" else fun.map(self.n)
        self._buf, self._eval = mapped.buffer()
        self._args = [np.zeros((self.n, fun.numel_in(i))) for i in range(fun.n_in())]
        self._shapes = [(fun.size2_out(i), fun.size1_out(i)) for i in range(fun.n_out())]
        self._res = [np.zeros((self.n,) + shape) for shape in self._shapes]
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buf.set_res(i, memoryview(r))

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        """Inputs (N, size of input i) each; outputs (N, rows, cols) each (fresh arrays)."""
        for a, value in zip(self._args, args):
            np.copyto(a, np.reshape(value, a.shape))
        self._eval()
        return [r.transpose(0, 2, 1).copy() for r in self._res]
