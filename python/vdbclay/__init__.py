"""vdbclay: virtual clay on sparse OpenVDB grids (Druon, Crosnier, Brigandat 2003).

Clay is an exact integer mass per voxel; a cellular automaton moves the excess of cells over Tc to
cells under it. Coordinates are voxel indices (y up); numpy arrays are dense boxes indexed
[x, y, z]. Sculptor.run returns the run's report: the dict of `vdbclay run --stats` (the same keys,
from the same JSON text).

Threads: calls on objects that share a grid (a Clay, its Automaton, a Sculptor and its clay) run one
after the other, a call waiting with the GIL released for the one running on that grid; long calls
release the GIL. Ctrl-C stops Sculptor.run and run_frame, Automaton.run and settle, and make_clay
within a step and raises KeyboardInterrupt, the object still exact. Memory: set_memory_budget()
and the calls' memory_budget argument, as `vdbclay run --memory-budget`. See docs/INTEROP.md and
help(vdbclay._vdbclay), help(vdbclay.Automaton), help(vdbclay.Sculptor), ...
"""
import ctypes
import ctypes.util

# libopenvdb must be loaded before the extension's libvdbclay: Python loads extensions with
# RTLD_LOCAL, and when libvdbclay's copies of OpenVDB's template statics (GNU unique symbols such as
# the tree type names) are registered first, openvdb::initialize() reads a name never set and
# crashes. Loading libopenvdb on its own first makes its copies the ones everybody uses.
_openvdb = ctypes.util.find_library("openvdb")
if _openvdb:
    try:
        ctypes.CDLL(_openvdb)
    except OSError:
        pass

from . import _vdbclay  # noqa: E402
from ._vdbclay import *  # noqa: E402,F401,F403
from ._vdbclay import Error, __version__  # noqa: E402,F401

# The public names (the extension's classes and functions): help(vdbclay) lists them, and
# `from vdbclay import *` takes exactly these.
__all__ = sorted(name for name in dir(_vdbclay) if not name.startswith("_"))
