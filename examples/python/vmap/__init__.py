"""vmap: a visual memory for robots, from Python (examples/python.md).

Key images from a camera stream (García-Pintos et al. 2023), loop closures (LFM-LCD,
Zhu et al. 2021) and localization in a memory kept in SQLite, on NumPy images without
copies. Everything is defined by the compiled extension vmap._vmap; its type stubs are
in __init__.pyi.
"""

from ._vmap import *  # noqa: F401,F403
from ._vmap import __version__  # noqa: F401
from . import _vmap

# The classes are defined by the extension; they are used (and documented, printed in
# tracebacks) as vmap.X.
for _name in dir(_vmap):
    _obj = getattr(_vmap, _name)
    if isinstance(_obj, type) and getattr(_obj, "__module__", "") == "vmap._vmap":
        _obj.__module__ = "vmap"
del _name, _obj
