"""The compiled kernels, ahead of time: the tree's (``rhbl/_kernels.py``), the laser's
(``server/_laser_kernels.py``) and the scan payload reader's (``client/behaviour/
_payload_kernels.py``) numba functions compiled into extension modules when rhbl is
installed (``pip install``, ``make install``, the image's wheel), so that a process loads them
in about a millisecond and imports no numba (numba's own set-up is about a second per process).

Everything else about the package is in pyproject.toml. Each kernel module names its exported
functions and their signatures (``aot_exports()``); the extension records the checksum of the
kernels' source files (``source_hash()`` of the package's numba-free layout module), and the
package uses it only while that matches its source (else numba's kernels: same answers, slower
start). Without numba or a C compiler at build time the extensions are skipped (optional): the
package then runs numba's kernels, compiled on first use.
"""

from __future__ import annotations

import importlib
import sys
import types
from pathlib import Path

from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CompileError

ROOT = Path(__file__).resolve().parent
# (package, kernel module, its numba-free module with source_hash(), extension module)
KERNELS = (
    ("rhbl", "_kernels", "_layout", "_kernels_aot"),
    ("server", "_laser_kernels", "_laser_layout", "_laser_aot"),
    ("client.behaviour", "_payload_kernels", "_payload_layout", "_payload_aot"),
)


def _module(package: str, name: str) -> types.ModuleType:
    """``package.name`` imported from this source tree without running the package's
    ``__init__`` (which imports the package's dependencies, not needed to compile)."""
    parts = package.split(".")
    for depth in range(1, len(parts) + 1):  # the package and its parents, as stubs
        stub_name = ".".join(parts[:depth])
        if stub_name not in sys.modules:
            stub = types.ModuleType(stub_name)
            stub.__path__ = [str(ROOT.joinpath(*parts[:depth]))]
            sys.modules[stub_name] = stub
    return importlib.import_module(f"{package}.{name}")


def _numba_flags() -> None:
    """Compile as the kernels' ``njit`` does: numpy's error model (a division by zero gives
    inf, as the laser relies on) and the GIL released while a kernel runs."""
    import numba.pycc.compiler as pycc_compiler

    compile_extra = pycc_compiler.compile_extra
    if getattr(compile_extra, "rhbl", False):
        return

    def compile_like_njit(typingctx, targetctx, func, args, return_type, flags, *a, **kw):
        flags.error_model = "numpy"
        flags.release_gil = True
        return compile_extra(typingctx, targetctx, func, args, return_type, flags, *a, **kw)

    compile_like_njit.rhbl = True
    pycc_compiler.compile_extra = compile_like_njit


def _extension(package: str, kernels: str, layout: str, name: str):
    from numba.pycc import CC

    cc = CC(name, source_module=_module(package, kernels))
    for symbol, (func, signature) in _module(package, kernels).aot_exports().items():
        cc.export(symbol, signature)(getattr(func, "py_func", func))
    checksum = _module(package, layout).source_hash()
    cc.export("source_hash", "int64()")(lambda: checksum)
    ext = cc.distutils_extension()
    ext.optional = True  # no C compiler: numba's kernels at run time
    return ext


class BuildKernels(build_ext):
    """``build_ext`` that lets numba generate the kernels' object code before linking."""

    def build_extension(self, ext):
        prepare = getattr(ext, "_prepare_object_files", None)
        if prepare is not None:
            try:
                _numba_flags()
                prepare(self)
            except Exception as exc:  # a numba whose compiler differs: skipped, as optional
                raise CompileError(f"numba could not compile {ext.name}: {exc!r}") from exc
        super().build_extension(ext)


def extensions() -> list:
    try:
        import numba.pycc  # noqa: F401 (numba's ahead-of-time compiler, setuptools needed)
    except ImportError as exc:
        print(f"setup.py: no ahead-of-time kernels ({exc}): numba compiles them on first use",
              file=sys.stderr)
        return []
    try:
        return [_extension(*k) for k in KERNELS]
    except RuntimeError as exc:  # numba's toolchain check: no C compiler
        print(f"setup.py: no ahead-of-time kernels (no working C compiler: "
              f"{str(exc).splitlines()[0]}): numba compiles them on first use", file=sys.stderr)
        return []


setup(ext_modules=extensions(), cmdclass={"build_ext": BuildKernels})
