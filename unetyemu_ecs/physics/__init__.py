"""Everything that touches PyBullet; the only package that imports it.

PyBullet prints its build date on stderr when first imported; that line is noise in a command-line
tool's output, so the first import happens here with the C-level stderr silenced.
"""

from __future__ import annotations

import os
import sys


def _import_pybullet_quietly() -> None:
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            try:
                import pybullet  # noqa: F401
            finally:
                os.dup2(saved, 2)
    finally:
        os.close(saved)


_import_pybullet_quietly()
