"""vmap: a visual memory for robots, from Python (examples/python.md).

Key images from a camera stream (García-Pintos et al. 2023), loop closures (LFM-LCD,
Zhu et al. 2021) and localization in a memory kept in SQLite, on NumPy images without
copies. Everything is defined by the compiled extension vmap._vmap; its type stubs are
in __init__.pyi.
"""

from ._vmap import *  # noqa: F401,F403
from ._vmap import __version__  # noqa: F401
