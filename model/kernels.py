"""Compiled element kernels, cached on disk, evaluated for a whole batch of elements in one call.

Small models are dominated by Python-to-CasADi call overhead, so each element kernel is generated to C
once, wrapped in a loop over elements, compiled to a shared library and called through ``ctypes`` on
contiguous numpy buffers: one call per element type per assembly, no copies.

Cache (after PyBaMM's ahead-of-time compile): the key is a SHA-256 of what defines the kernel (:func:`kernel_key`:
its name and sizes, the text of the code that generates it, :data:`GENERATORS`, the wrapper source and the CasADi
version) and of the compiler command. The CasADi function itself is not serialised for the key: that cost a fresh
process 0.1-0.3 s for the beam's third-derivative kernel alone, on every cache hit. The library is written to a
temporary file and renamed atomically, so concurrent processes never see half a file. The directory is
``$FLEXOPT_CACHE_DIR`` or ``~/.cache/flexopt/kernels``. Without a C compiler the kernel falls back to
CasADi's own virtual machine (``Function.map``) with a ``KernelPerformanceWarning``: same numbers, slower.

The hand-written C of the compiled routes lives in ``model/native/*.c`` (package data): the kernels' batch
entry (kernel_batch.c), the one-call assembly (assemble.c), the linear algebra (linalg.c) and the Newton loop
(newton_point.c). :func:`native_source` reads one and puts the definitions its opening comment asks for in
front (sizes, the LAPACK integer, the slot tables generated from their one Python list by :func:`c_enum`);
:func:`native_library` compiles that text with :func:`shared_library`, keyed by its hash.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import re
import shutil
import subprocess
import tempfile
import warnings
from collections.abc import Callable, Iterable, Sequence
from functools import cache
from importlib import resources
from pathlib import Path

import casadi as ca
import numpy as np

from .elements import KernelSpec
from .errors import KernelBuildError

__all__ = [
    "CompiledKernel",
    "compiled",
    "cache_dir",
    "shared_library",
    "native_source",
    "native_library",
    "native_files",
    "c_enum",
    "batch_definitions",
    "kernel_key",
    "generator_hash",
    "GENERATORS",
    "KernelPerformanceWarning",
    "FLAGS",
]


class KernelPerformanceWarning(UserWarning):
    """A kernel runs in CasADi's virtual machine because no C compiler was found."""


def cache_dir() -> Path:
    """Directory of the compiled-kernel cache."""
    env = os.environ.get("FLEXOPT_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "flexopt" / "kernels"


def _compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")


#: The compiler flags of every build (part of the cache key). ``-Wall -Wextra``: the sources in model/native compile
#: without a warning (tests/test_native.py builds each with ``-Werror``); CasADi's generated code may warn, which
#: is not shown (only a failed build's messages are).
FLAGS = ("-O2", "-shared", "-fPIC", "-fno-math-errno", "-Wall", "-Wextra")


def native_files() -> list[str]:
    """The file names of the C sources in model/native (package data)."""
    folder = resources.files(__package__).joinpath("native")
    return sorted(f.name for f in folder.iterdir() if f.name.endswith((".c", ".h")))


def native_source(file: str, defines: Sequence[tuple[str, object]] = (), prelude: str = "") -> str:
    """The C source ``model/native/<file>`` preceded by ``prelude`` and one ``#define NAME value`` line per entry of
    ``defines``: the text that is compiled, and hashed for the cache key."""
    text = resources.files(__package__).joinpath("native", file).read_text()
    return prelude + "".join(f"#define {k} {v}\n" for k, v in defines) + text


def native_library(name: str, file: str, defines: Sequence[tuple[str, object]] = (), prelude: str = "") -> ctypes.CDLL:
    """:func:`native_source` compiled to a shared library (:func:`shared_library`, the key the hash of that text)."""
    source = native_source(file, defines, prelude)
    return shared_library(name, (source,), lambda: source)


def c_enum(names: Iterable[str], tag: str) -> str:
    """A C ``enum tag { NAME0, NAME1, ... };`` of ``names`` upper-cased in their order, so C indexes a table by the
    names of the Python list that lays it out. Raises ValueError for a name that is no C identifier or two names
    equal up to case (they would be one enumerator)."""
    names = list(names)
    upper = [n.upper() for n in names]
    bad = [n for n in names if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", n)]
    if bad or len(set(upper)) != len(upper):
        raise ValueError(f"slot names {bad or names} are not distinct C identifiers up to case")
    return f"enum {tag} {{ " + ", ".join(upper) + " };\n"


def shared_library(name: str, key_parts: tuple[str, ...], source, cc: str | None = None) -> ctypes.CDLL:
    """Compile C code to a shared library once and load it from the disk cache afterwards.

    ``key_parts`` identify the code (hashed with the compiler and its flags: the library is rebuilt when
    any of them changes); ``source()`` returns the C source and is called only on a cache miss, so code
    generation costs nothing once cached. The library is written to a temporary file and renamed
    atomically, so concurrent processes never load half a file. Raises KernelBuildError when the compiler
    fails or no compiler is found.
    """
    cc = cc or _compiler()
    if cc is None:
        raise KernelBuildError(f"no C compiler found to build '{name}'; install gcc or set CC")
    key = hashlib.sha256()
    for part in (*key_parts, cc, " ".join(FLAGS)):
        key.update(part.encode())
    directory = cache_dir()
    lib_path = directory / f"{name}-{key.hexdigest()[:24]}.so"
    if not lib_path.exists():
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=directory) as tmp:
            src = Path(tmp) / (name + ".c")
            src.write_text(source())
            tmp_lib = Path(tmp) / "lib.so"
            proc = subprocess.run([cc, *FLAGS, str(src), "-o", str(tmp_lib), "-lm"], capture_output=True, text=True)
            if proc.returncode != 0:
                raise KernelBuildError(
                    f"compiling '{name}' failed ({cc}): {proc.stderr[-2000:]}; check the C compiler or unset CC"
                )
            os.replace(tmp_lib, lib_path)
    try:
        return ctypes.CDLL(str(lib_path))
    except OSError as exc:  # a corrupt cache entry: rebuild once
        lib_path.unlink(missing_ok=True)
        raise KernelBuildError(f"loading '{name}' from {lib_path} failed: {exc}; retry") from exc


def batch_definitions(spec: KernelSpec) -> tuple[tuple[str, object], ...]:
    """What model/native/kernel_batch.c needs defined before it for the kernel of ``spec``: its CasADi function's
    name, the batch entry's name, the row sizes and CasADi's work sizes."""
    f = spec.function
    name = f.name()
    return (
        ("KERNEL", name),
        ("BATCH", name + "_batch"),
        ("N_IN", spec.n_in),
        ("N_OUT", spec.n_out),
        ("SZ_ARG", max(f.sz_arg(), 1)),
        ("SZ_RES", max(f.sz_res(), 1)),
        ("SZ_IW", f.sz_iw()),
        ("SZ_W", f.sz_w()),
    )


#: The files whose code generates every :class:`KernelSpec`'s CasADi function: their text stands in the cache key
#: for the function (with CasADi's version, which builds it from that code). tests/test_kernels.py checks that no
#: other file constructs a KernelSpec and that the code building one reaches no other flexopt module.
GENERATORS = (Path(__file__).with_name("elements.py"),)


@cache
def generator_hash() -> str:
    """SHA-256 of the text of :data:`GENERATORS` (read once per process)."""
    h = hashlib.sha256()
    for f in GENERATORS:
        h.update(f.read_bytes())
    return h.hexdigest()


def kernel_key(spec: KernelSpec, wrapper: str) -> tuple[str, ...]:
    """What defines the compiled kernel of ``spec`` with the batch ``wrapper`` (:func:`shared_library` adds the
    compiler and its flags): the kernel's name, its input, output and CasADi instruction counts, the hash of the
    code that generates it (:func:`generator_hash`), the wrapper source (the work sizes included) and the CasADi
    version. None of it needs the function serialised."""
    f = spec.function
    shape = f"{spec.n_in} {spec.n_out} {f.nnz_in()} {f.nnz_out()} {f.n_instructions()}"
    version = ca.__version__  # type: ignore[attr-defined]  # casadi's stubs omit the module's __version__
    return (spec.name, shape, generator_hash(), wrapper, version)


class CompiledKernel:
    """A batch evaluator of one element kernel: ``out[k] = f(in[k])`` for every row ``k``."""

    def __init__(self, spec: KernelSpec) -> None:
        self.spec = spec
        self.n_in = spec.n_in
        self.n_out = spec.n_out
        self._lib: ctypes.CDLL | None = None
        self._fn: Callable[[int, int, int], int] | None = None  # the compiled batch entry
        self._address: int | None = None
        self._vm: ca.Function | None  # CasADi's virtual machine, where no C compiler is found
        cc = _compiler()
        if cc is None:
            warnings.warn(
                f"no C compiler found: kernel '{spec.name}' runs in CasADi's virtual machine (slower); "
                "install gcc to compile it",
                KernelPerformanceWarning,
                stacklevel=2,
            )
            self._vm = spec.function
        else:
            self._vm = None
            self._load(cc)

    def _load(self, cc: str) -> None:
        f = self.spec.function
        name = f.name()
        wrapper = native_source("kernel_batch.c", batch_definitions(self.spec))

        def source() -> str:
            with tempfile.TemporaryDirectory() as tmp:
                cg = ca.CodeGenerator(name + ".c", {"with_header": False, "casadi_int": "long long"})
                cg.add(f)
                cg.generate(tmp + os.sep)
                return (Path(tmp) / (name + ".c")).read_text() + wrapper

        lib = shared_library(name, kernel_key(self.spec, wrapper), source, cc)
        fn = getattr(lib, name + "_batch")
        fn.restype = ctypes.c_int
        fn.argtypes = [ctypes.c_longlong, ctypes.c_void_p, ctypes.c_void_p]
        self._lib, self._fn = lib, fn
        self._address = ctypes.cast(fn, ctypes.c_void_p).value

    @property
    def address(self) -> int | None:
        """Address of the compiled batch entry ``int f(long long n, const double* in, double* out)`` (C code
        calls it through a pointer, model/assembly.py), or None when the kernel runs in CasADi's VM."""
        return self._address

    def __call__(self, inputs: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Evaluate on ``inputs`` of shape (n, n_in); returns (n, n_out)."""
        inputs = np.ascontiguousarray(inputs, dtype=np.float64)
        n = inputs.shape[0]
        if inputs.shape[1] != self.n_in:
            raise ValueError(f"kernel '{self.spec.name}' expects {self.n_in} inputs, got {inputs.shape[1]}")
        if out is None:
            out = np.empty((n, self.n_out))
        if n == 0:
            return out
        if self._fn is not None:
            if self._fn(n, inputs.ctypes.data, out.ctypes.data):
                raise KernelBuildError(f"kernel '{self.spec.name}' reported an evaluation error")
            return out
        assert self._vm is not None  # no compiled entry: __init__ kept the kernel for CasADi's VM
        res = self._vm.map(n)(inputs.T)
        out[:] = np.asarray(res).T
        return out


_CACHE: dict[str, CompiledKernel] = {}


def compiled(spec: KernelSpec) -> CompiledKernel:
    """The compiled kernel of ``spec``, built (or loaded from the disk cache) once per process."""
    k = _CACHE.get(spec.name)
    if k is None:
        k = _CACHE[spec.name] = CompiledKernel(spec)
    return k
