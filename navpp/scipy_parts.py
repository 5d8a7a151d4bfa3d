"""Compiled scipy modules loaded on their own, without the Python package around them.

``import scipy.linalg`` runs the whole package (and, through its array-API layer, imports
``numpy.f2py``): about 0.2 s of CPU, a tenth of a run on the 1-hour log.  A run needs two
compiled modules of it: ``scipy.linalg.cython_blas``, which numba imports on its first kernel
(cached or compiled) to check that BLAS is there and where its kernels look BLAS functions
up, and LAPACK's tridiagonal solver ``dgtsv`` of ``scipy.linalg._flapack`` (the clock-offset
spline, :mod:`navpp.ins.timing_estimates`; the same function ``scipy.linalg.get_lapack_funcs``
returns for float64).  :func:`extension` loads such a module from its file beside the
package's sources and registers it under its full name, so that an ``import`` of that name
finds it; a later ``import scipy.linalg`` still runs the package as usual and uses the same
module object (only the attribute ``scipy.linalg.cython_blas`` is not bound then;
``from scipy.linalg import cython_blas`` works).
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.machinery
import importlib.util
import os
import sys
from types import ModuleType


def extension(name: str) -> ModuleType:
    """The compiled module ``name`` (e.g. ``"scipy.linalg._flapack"``): the one already imported,
    else loaded from its file on its own when its package is not imported yet, else imported
    the usual way (also when its file is not found)."""
    if name in sys.modules:
        return sys.modules[name]
    package, _, leaf = name.rpartition(".")
    top, _, inner = package.partition(".")
    if package not in sys.modules:
        spec = importlib.util.find_spec(top)
        for root in (spec.submodule_search_locations or []) if spec is not None else []:
            for suffix in importlib.machinery.EXTENSION_SUFFIXES:
                path = os.path.join(root, *inner.split("."), leaf + suffix)
                if os.path.isfile(path):
                    return _load(name, path)
    return importlib.import_module(name)


def _load(name: str, path: str) -> ModuleType:
    """The extension module at ``path`` executed and registered as ``name``."""
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        return importlib.import_module(name)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def preload_blas() -> None:
    """``scipy.linalg.cython_blas`` loaded on its own (:func:`extension`) before numba's first
    kernel imports it; nothing when scipy is not installed (numba then has no BLAS either way)."""
    with contextlib.suppress(ImportError):
        extension("scipy.linalg.cython_blas")
